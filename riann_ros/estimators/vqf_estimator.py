"""VQF (Laidig & Seel 2023) through the ``vqf`` package, 6D or 9D output (ROS-free).

D. Laidig, T. Seel, "VQF: Highly accurate IMU orientation estimation with bias estimation and magnetic
disturbance rejection", Information Fusion 91:187-204, 2023, https://doi.org/10.1016/j.inffus.2022.10.014.
The C++ implementation of the ``vqf`` package (MIT) does the work; this class only adapts it to the
:class:`~riann_ros.estimators.base.AttitudeEstimator` interface.

* **output** — ``getQuat6D()`` / the ``quat6D`` batch result: gyroscope + accelerometer fusion, sensor
  frame → VQF's 6D earth frame, whose z axis points up (the accelerometer at rest maps onto +z) and
  whose heading is arbitrary: it starts at the sensor's initial heading and drifts with the remaining
  gyro bias about z (no magnetometer). So it is sensor → world ENU up to a heading offset, like the
  other 6D estimators here.
* **magnetometer (9D)** — with a field (``mag``, converted to µT for VQF) the output is ``getQuat9D()``:
  VQF's heading correction toward the magnetic field, its earth frame ENU with y = magnetic north,
  with VQF's own magnetic disturbance rejection (``mag_dist_rejection``) and time constant
  ``tau_mag`` (``tauMag``). The correction changes the heading only, so the inclination is the 6D one.
  Samples without a field (NaN or zero rows, ``mag=None``) skip ``updateMag``: the heading follows the
  gyro. The output is always ``quat9D``: before the first field VQF's heading offset is the identity,
  so it equals ``quat6D`` exactly, and after the magnetometer stops the heading continues without a jump.
  Where the online magnetometer calibration changes the calibration the field gets and VQF's heading disagrees
  with it (a :class:`~riann_ros.magcal.changes.Realign` event), VQF's magnetic state starts as at its construction
  (the batch is cut there: ``updateBatch`` per piece, the same numbers as per-sample calls).
* **dt** — VQF is built for a fixed sampling time ``Ts`` given at construction. The filter is created at
  the first sample with ``Ts`` = that sample's dt (the stream gives the first sample ``1/nominal_rate``;
  ``riann_ros.defaults.FALLBACK_DT_S`` if that dt is not positive). Every sample's gyroscope reading is then scaled by
  ``dt / Ts`` before it goes in, so VQF's strapdown integration (angle = |ω|·Ts) integrates over the
  sample's true dt, also across jitter and short gaps. The accelerometer low-pass and the rest
  detector still count time in samples of ``Ts``: if the real rate differs persistently from the first
  dt, ``tau_acc`` and the bias-estimation time constants scale with the ratio (``reset()`` re-picks Ts).
  Because the scaling is per row, the batch path is ``updateBatch(gyr·dt/Ts, acc)``, which gives the
  same numbers as per-sample ``update`` calls.
* **degenerate input** — a zero (or non-finite) accelerometer sample is skipped by VQF (gyro-only
  step); a non-finite gyro sample counts as zero rate; non-finite or negative dt counts as 0.
* **σ** — ``sigma_model`` 'constant' (default): the documented inclination σ; 'state': per sample from VQF's state
  (its bias estimate's σ, the motion, the time since it started: :mod:`~.vqf_sigma`), the attitude unchanged.
* **parameters** — ``tau_acc`` (VQF ``tauAcc``), ``motion_bias_est`` (``motionBiasEstEnabled``),
  ``rest_bias_est`` (``restBiasEstEnabled``) and ``bias_clip`` (``biasClip``, °/s), defaults from
  ``vqf.VQF().params``; all but ``bias_clip`` can change at run time through VQF's own setters
  (``setTauAcc`` adapts the filter states to the new coefficients). ``bias_clip`` matters beyond the
  clipping: VQF detects rest only while the low-passed gyro stays below it, so with the default 2 °/s a
  turn-on bias of 3 °/s is learned neither at rest nor, fully, in motion.
"""

from __future__ import annotations

import numpy as np
from numpy.typing import ArrayLike, NDArray
from vqf import VQF

from riann_ros import defaults
from riann_ros.estimators.base import Array, ParamSpec
from riann_ros.estimators.classical import Batch, ClassicalFilter
from riann_ros.estimators.common import BIAS_KEY, bias_text, cut_at
from riann_ros.estimators.vqf_sigma import VqfStateSigma
from riann_ros.magcal.changes import field_disagrees
from riann_ros.magcal.input import MAG_CAL_PARAMS

# defaults of vqf 2.1.2 (VQFParams)
DEFAULT_TAU_ACC = 3.0
DEFAULT_MOTION_BIAS_EST = True
DEFAULT_REST_BIAS_EST = True
DEFAULT_BIAS_CLIP = 2.0  # °/s
DEFAULT_TAU_MAG = 9.0  # s
DEFAULT_MAG_DIST_REJECTION = True
TESLA_TO_UT = 1e6
#: VQF's state of its heading correction: its initialisation gain and the disturbance rejection's field reference
_VQF_MAG_STATE = ("kMagInit", "lastMagDisAngle", "lastMagCorrAngularRate", "magDistDetected", "magRefNorm",
                  "magRefDip", "magUndisturbedT", "magRejectT", "magCandidateNorm", "magCandidateDip",
                  "magCandidateT", "magNormDip", "magNormDipLpState")


class VqfEstimator(ClassicalFilter):
    """VQF 6D (gyr + acc) with rest and motion gyro-bias estimation."""

    name = "vqf"
    PARAMS = (
        ParamSpec(
            "tau_acc",
            DEFAULT_TAU_ACC,
            "Time constant (s) of the accelerometer low-pass in the inclination correction (VQF tauAcc): "
            "smaller trusts the accelerometer more. Default 3.0 = the vqf package default.",
            min=0.01,
            max=1000.0,
            runtime=True,
        ),
        ParamSpec(
            "motion_bias_est",
            DEFAULT_MOTION_BIAS_EST,
            "Estimate the gyro bias during motion (VQF motionBiasEstEnabled). Default true = vqf default.",
            runtime=True,
        ),
        ParamSpec(
            "rest_bias_est",
            DEFAULT_REST_BIAS_EST,
            "Detect rest and estimate the gyro bias at rest (VQF restBiasEstEnabled). Default true = vqf default.",
            runtime=True,
        ),
        ParamSpec(
            "bias_clip",
            DEFAULT_BIAS_CLIP,
            "deg/s; largest gyro bias VQF estimates (VQF biasClip); rest is only detected while the low-passed gyro "
            "stays below it, so a turn-on bias above it is never learned. Default 2.0 = the vqf default; raise it "
            "for sensors with a larger turn-on bias.",
            min=0.1,
            max=100.0,
        ),
        ParamSpec(
            "tau_mag",
            DEFAULT_TAU_MAG,
            "s; time constant of the heading correction toward the magnetometer (VQF tauMag; 9D only). "
            "Default 9.0 = the vqf default.",
            min=0.01,
            max=1000.0,
            runtime=True,
        ),
        ParamSpec(
            "mag_dist_rejection",
            DEFAULT_MAG_DIST_REJECTION,
            "Detect magnetic disturbances (field norm and dip against a learned reference) and hold the heading "
            "with the gyro while disturbed (VQF magDistRejectionEnabled; 9D only). Default true = vqf default.",
            runtime=True,
        ),
        ParamSpec(
            "sigma_model",
            "constant",
            "Inclination sigma reported per sample: 'constant' (the documented 2 deg) or 'state' (from VQF's state: "
            "its bias estimate's sigma, the motion, the time since its start; riann_ros/estimators/vqf_sigma.py). The "
            "attitude is the same either way.",
            choices=("constant", "state"),
        ),
        *MAG_CAL_PARAMS,
    )

    def _reset_filter(self) -> None:
        self._vqf: VQF | None = None
        self._ts: float | None = None
        self._mag_used = False
        self._state_sigma: VqfStateSigma | None = None
        if self.params["sigma_model"] == "state":
            self._state_sigma = VqfStateSigma(float(self.params["tau_acc"]))

    def heading_observed(self) -> bool:
        return self._mag_used and self._vqf is not None and not self._vqf.getMagDistDetected()

    @property
    def bias(self) -> Array:
        """VQF's current gyro-bias estimate (rad/s, in units of the dt-scaled gyro), zeros before start."""
        if self._vqf is None:
            return np.zeros(3)
        return np.asarray(self._vqf.getBiasEstimate()[0], dtype=float)

    def diagnostics(self) -> dict[str, str]:
        return {BIAS_KEY: bias_text(self.bias)}

    def _on_params_changed(self) -> None:
        if self._vqf is None:
            return
        self._vqf.setTauAcc(float(self.params["tau_acc"]))
        self._vqf.setMotionBiasEstEnabled(bool(self.params["motion_bias_est"]))
        self._vqf.setRestBiasEstEnabled(bool(self.params["rest_bias_est"]))
        self._vqf.setTauMag(float(self.params["tau_mag"]))
        self._vqf.setMagDistRejectionEnabled(bool(self.params["mag_dist_rejection"]))

    def _ensure(self, first_dt: float) -> tuple[VQF, float]:
        """The filter and its Ts, built at the first sample."""
        if self._vqf is None or self._ts is None:
            self._ts = float(first_dt) if first_dt > 0.0 else defaults.FALLBACK_DT_S
            self._vqf = VQF(
                self._ts,
                tauAcc=float(self.params["tau_acc"]),
                motionBiasEstEnabled=bool(self.params["motion_bias_est"]),
                restBiasEstEnabled=bool(self.params["rest_bias_est"]),
                biasClip=float(self.params["bias_clip"]),
                tauMag=float(self.params["tau_mag"]),
                magDistRejectionEnabled=bool(self.params["mag_dist_rejection"]),
            )
        return self._vqf, self._ts

    def update(self, acc: ArrayLike, gyr: ArrayLike, dt: float, mag: ArrayLike | None = None) -> Array:
        b = self._batch(np.reshape(acc, (1, 3)), np.reshape(gyr, (1, 3)), [dt],
                        None if mag is None else np.reshape(mag, (1, 3)))
        a, g, h = b.acc, b.gyr, b.dt
        v, ts = self._ensure(float(h[0]))
        m = _field_ut(b.mag, 1)[0]
        self._mag_used = bool(m.any())
        if b.realign:
            self._restart_heading(b.realign[0].sd_rad, m)
        gs = np.ascontiguousarray(g[0] * (h[0] / ts))
        if self._mag_used:
            v.update(gs, np.ascontiguousarray(a[0]), m)
        else:
            v.update(gs, np.ascontiguousarray(a[0]))
        if self._state_sigma is not None:
            b, sd = v.getBiasEstimate()
            self._state_sigma.take(a, gs[None, :], h, np.asarray(b)[None, :], np.array([sd]))
        return np.asarray(v.getQuat9D(), dtype=float).copy()

    def _run(self, batch: Batch) -> Array:
        a, g, h = batch.acc, batch.gyr, batch.dt
        if len(a) == 0:
            return np.empty((0, 4))
        v, ts = self._ensure(float(h[0]))
        m = _field_ut(batch.mag, len(a))
        g = np.ascontiguousarray(g * (h / ts)[:, None])  # zero rows: VQF skips updateMag
        self._mag_used = bool(m[-1].any())
        a = np.ascontiguousarray(a)
        out, bias, bias_sd = [], [], []
        for i, j, sd in cut_at(batch.realign, len(a)):
            if sd is not None:
                self._restart_heading(sd, m[i])
            r = v.updateBatch(np.ascontiguousarray(g[i:j]), np.ascontiguousarray(a[i:j]), np.ascontiguousarray(m[i:j]))
            out.append(r["quat9D"])
            bias.append(r["bias"])
            bias_sd.append(r["biasSigma"])
        if self._state_sigma is not None:
            self._state_sigma.take(a, g, h, np.concatenate(bias), np.concatenate(bias_sd))
        return np.array(np.concatenate(out), dtype=float)

    def sigma(self, fields: NDArray[np.bool_]) -> Array:
        """With ``sigma_model`` 'state' the inclination's σ from VQF's state (:mod:`~.vqf_sigma`), else the constant;
        the heading's as :meth:`ClassicalFilter.sigma`."""
        out = super().sigma(fields)
        if self._state_sigma is not None:
            out[:, 0] = self._state_sigma.last(len(out))
        return out

    def _restart_heading(self, sd_rad: float, m_ut: Array) -> None:
        """VQF's realign event: the online calibration changed the calibration the field gets (``m_ut`` the row's
        field, ``sd_rad`` the heading σ it adds): where VQF's heading disagrees with it
        (:func:`~riann_ros.magcal.changes.field_disagrees`) VQF's magnetic
        part starts as at its construction (its heading initialisation over ``tau_mag``, a new field reference for
        the disturbance rejection); its inclination, gyro bias and current heading are kept."""
        v, ts = self._vqf, self._ts
        assert v is not None and ts is not None
        q = v.getQuat9D()
        if not field_disagrees((q[0], q[1], q[2], q[3]), (m_ut[0], m_ut[1], m_ut[2]), sd_rad):
            return
        fresh = VQF(ts, tauMag=float(self.params["tau_mag"])).state
        state = v.state
        state.update({k: fresh[k] for k in _VQF_MAG_STATE})
        v.state = state


def _field_ut(mag: list | None, n: int) -> Array:
    """The field rows (a row None: no field) as a C-contiguous (n, 3) array in µT; rows without a usable field are
    zeros."""
    if mag is None:
        return np.zeros((n, 3))
    rows = [(np.nan, np.nan, np.nan) if u is None else u for u in mag]
    m = np.array(rows, dtype=float).reshape(n, 3) * TESLA_TO_UT
    m[~np.isfinite(m).all(axis=1)] = 0.0
    return np.ascontiguousarray(m)
