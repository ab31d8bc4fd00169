"""A causal gyroscope-bias front end: VQF's bias estimator in front of another filter (ROS-free).

MEMS gyroscopes start with a bias of a few °/s (one public MAV dataset has 4.4 °/s), which a filter
that trusts the gyro integrates into a growing tilt. :class:`GyroBiasFrontEnd` runs the bias
estimation of VQF (Laidig & Seel 2023, the ``vqf`` package) on the same samples the filter gets, and
gives the bias known *before* each sample, to be subtracted from that sample's gyro: causal, and the
filter behind it never sees its own output fed back.

VQF estimates the bias at rest (a rest detector on the low-passed gyro and accelerometer) and in
motion (from the inclination error of its own accelerometer correction). Two of its parameters are
set for a front end that must learn a turn-on bias quickly:

* ``clip`` (°/s, VQF ``biasClip``, default 2): the estimate is clipped at this value *and* rest is
  detected only while the low-passed gyro stays below it, so with the default a turn-on bias of 3 °/s
  is learned neither at rest nor, fully, in motion. The front end uses 8 °/s.
* ``sigma_init`` (°/s, VQF ``biasSigmaInit``, default 0.5): the prior standard deviation of the
  bias. A consumer MEMS gyro's turn-on bias is of the order of several °/s, so the front end uses
  3 °/s; with VQF's 0.5 °/s prior the motion estimate needs minutes to learn a 3 °/s bias.

VQF wants a constant sample time ``Ts``; a front end fed at another step scales the gyro by
``dt / Ts`` (the strapdown integration then covers the true ``dt``).
"""

from __future__ import annotations

import numpy as np
from numpy.typing import ArrayLike
from vqf import VQF

from riann_ros.defaults import FALLBACK_DT_S
from riann_ros.estimators.base import Array
from riann_ros.params import ParamSpec

DEFAULT_CLIP = 8.0  # °/s
DEFAULT_SIGMA_INIT = 3.0  # °/s


def front_end_params(default_on: bool, what: str) -> tuple[ParamSpec, ...]:
    """The front end's parameters, for an estimator that offers it (``what`` names the filter behind)."""
    return (
        ParamSpec("gyro_bias_estimation", default_on,
                  f"Subtract a causal gyro-bias estimate (VQF's rest and motion bias estimation) from the gyro "
                  f"before {what}. The estimate appears in /diagnostics."),
        ParamSpec("bias_clip", DEFAULT_CLIP, "deg/s; largest gyro bias the front end estimates (VQF biasClip).",
                  min=0.1, max=100.0),
        ParamSpec("bias_sigma_init", DEFAULT_SIGMA_INIT,
                  "deg/s; prior std of the turn-on gyro bias (VQF biasSigmaInit).", min=0.0, max=100.0),
    )


class FrontEndSlot:
    """A front end that starts at an estimator's first sample (``ts`` = that sample's dt) and takes the
    raw samples with their own dt, for filters fed at the stream's steps (Madgwick, Mahony)."""

    def __init__(self, params: dict) -> None:
        self.on = bool(params["gyro_bias_estimation"])
        self.clip = float(params["bias_clip"])
        self.sigma_init = float(params["bias_sigma_init"])
        self.fe: GyroBiasFrontEnd | None = None

    def debias(self, acc: Array, gyr: Array, dt: Array) -> Array:
        """The gyro minus the bias known before each sample (``gyr`` itself when off)."""
        if not self.on or len(gyr) == 0:
            return gyr
        if self.fe is None:
            ts = float(dt[0]) if 0.0 < dt[0] < 1.0 else FALLBACK_DT_S
            self.fe = GyroBiasFrontEnd(ts, self.clip, self.sigma_init)
        return gyr - self.fe.update_batch(acc, gyr, dt)

    @property
    def bias(self) -> tuple[float, float, float]:
        return self.fe.bias if self.fe is not None else (0.0, 0.0, 0.0)


class GyroBiasFrontEnd:
    """VQF's gyro-bias estimate, one sample at a time or in batches (same numbers)."""

    def __init__(self, ts: float, clip: float = DEFAULT_CLIP, sigma_init: float = DEFAULT_SIGMA_INIT) -> None:
        self.clip = clip
        self.sigma_init = sigma_init
        self.bias: tuple[float, float, float] = (0.0, 0.0, 0.0)  # rad/s, known before the next sample
        self._vqf: VQF | None = None
        self.ts = ts
        self.set_ts(ts)

    def set_ts(self, ts: float) -> None:
        """(Re)build VQF for sample time ``ts`` (s), keeping the bias learned so far."""
        old = self._vqf
        self.ts = ts
        self._vqf = VQF(ts, biasClip=self.clip, biasSigmaInit=self.sigma_init, magDistRejectionEnabled=False)
        if old is not None:
            b, sigma = old.getBiasEstimate()
            self._vqf.setBiasEstimate(np.asarray(b, dtype=float), float(sigma))

    def update(self, acc: ArrayLike, gyr: ArrayLike, dt: float | None = None) -> None:
        """Take one sample (raw gyro, rad/s); afterwards :attr:`bias` is the estimate for the next one."""
        g = np.asarray(gyr, dtype=float)
        if dt is not None and dt != self.ts:
            g = g * (dt / self.ts)
        vqf = self._vqf
        assert vqf is not None
        vqf.update(np.ascontiguousarray(g), np.ascontiguousarray(acc, dtype=float))
        b = vqf.getBiasEstimate()[0]
        self.bias = (float(b[0]), float(b[1]), float(b[2]))

    def update_batch(self, acc: Array, gyr: Array, dt: Array | None = None) -> Array:
        """Take N samples; return the bias known before each of them (N, 3)."""
        g = np.asarray(gyr, dtype=float)
        if dt is not None:
            g = g * (np.asarray(dt, dtype=float) / self.ts)[:, None]
        vqf = self._vqf
        assert vqf is not None
        out = vqf.updateBatch(np.ascontiguousarray(g), np.ascontiguousarray(acc, dtype=float))
        before = np.vstack([np.asarray(self.bias)[None, :], out["bias"][:-1]])
        self._took_batch(out)
        b = out["bias"][-1]
        self.bias = (float(b[0]), float(b[1]), float(b[2]))
        return before

    def _took_batch(self, out: dict[str, Array]) -> None:
        """What a subclass keeps of VQF's batch outputs (``updateBatch``'s dict), before :attr:`bias` moves on."""
