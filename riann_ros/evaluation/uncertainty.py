"""Scoring the uncertainty an estimator reports beside its estimate (ROS-free).

Per scored sample the estimator's σ (rad): ``σ_i`` of the inclination per horizontal axis and ``σ_ψ`` of the
heading (:meth:`riann_ros.estimators.base.AttitudeEstimator.sigma`). The inclination error ``e_α`` (paper eq. 3) is
the length of the 2-D error of roll and pitch, so for a calibrated ``σ_i`` ``e_α²/σ_i²`` is χ² with 2 degrees of
freedom:

* NEES per degree of freedom: the mean of ``e_α² / (2 σ_i²)`` (1 when calibrated; > 1 overconfident);
* coverage of the 95 % region: the share of samples with ``e_α²/σ_i² ≤ χ²₂(0.95) = 5.991`` (95 % when calibrated);
* sharpness: the mean ``e_α`` of the samples in the top decile of ``σ_i`` over that of the bottom decile (deciles
  from a histogram of σ in :data:`BINS`, so a bag of any length is scored in bounded memory).

The heading the same way with one degree of freedom (``χ²₁(0.95) = 3.841``), on samples whose ``σ_ψ`` is below the
unobservable 180°, split into those corrected by a field and those held by the gyro after one (the field rejected or
absent): by the state the estimator reports with its σ
(:meth:`~riann_ros.estimators.base.AttitudeEstimator.heading_state`, run in process), else by the σ (at most
:data:`FIELD_USED_SD_DEG`: corrected; larger: held), as for the classical filters and a covariance read from a bag.
Samples without a σ (NaN) are not counted.

The reference has an error of its own (an optical system's marker and alignment error), which no estimator σ should
carry: with ``σ_ref`` (rad per axis, ``riann-bag-eval --reference-sd``) coverage and NEES are scored against
``σ² = σ_est² + σ_ref²`` on each axis (both tilt axes, the heading's). The split of the heading samples and the
σ histogram (sharpness, the plot) stay on the estimator's own σ. With ``σ_ref = 0`` the estimator's σ is used as it
is. The tables, ``--compare`` lines and the plot:
:mod:`riann_ros.evaluation.uncertainty_report`.
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np
from numpy.typing import NDArray

from riann_ros.defaults import MAG_HEADING_SD_DEG, YAW_FREE_SD_DEG
from riann_ros.estimators.base import HEADING_CORRECTED, HEADING_HELD

CHI2_2_95 = 5.991  # χ²₂(0.95)
CHI2_1_95 = 3.841  # χ²₁(0.95)
BINS = np.radians(np.logspace(-3, math.log10(180.0), 161))  # σ_i bin edges (rad), 0.001° … 180°
#: deg; where the estimator does not say its heading state, a heading σ at most this counts as "field used" (the
#: field corrects the heading), a larger one below 180° as "held": twice the field heading's own σ
#: (:data:`~riann_ros.defaults.MAG_HEADING_SD_DEG`), which the classical filters report with a field, plus room for
#: the share of a magnetometer calibration that is still converging (they report the two combined)
FIELD_USED_SD_DEG = 2.0 * MAG_HEADING_SD_DEG
MAG_SD = math.radians(FIELD_USED_SD_DEG) * (1.0 + 1e-9)
FREE_SD = math.radians(YAW_FREE_SD_DEG) * (1.0 - 1e-9)
KEYS = ("nees", "cover95_pct", "err_bottom_decile_deg", "err_top_decile_deg", "yaw_nees", "yaw_cover95_mag_pct",
        "yaw_cover95_held_pct", "n_yaw_mag", "n_yaw_held")


class UncertaintySums:
    """Running sums of the uncertainty scores of one scenario × estimator run."""

    def __init__(self, reference_sd: float = 0.0) -> None:
        self.reference_sd = reference_sd  # rad per axis: the reference's own error, added in quadrature to σ
        self.n = self.inside = 0
        self.nees = 0.0
        self.hist_n = np.zeros(len(BINS) + 1)
        self.hist_e = np.zeros(len(BINS) + 1)
        self.yaw = {"mag": [0, 0], "held": [0, 0]}  # [samples, inside the 95 % region]
        self.yaw_nees = 0.0

    def add(self, e: NDArray[np.float64], e_yaw: NDArray[np.float64], sigma: NDArray[np.float64]) -> None:
        """Scored samples: inclination and heading errors (rad) and their σ (n, 2) (NaN rows: none reported), or
        (n, 3) with the estimator's heading state (the codes of ``heading_state``; NaN: not said)."""
        ok = np.isfinite(sigma[:, :2]).all(axis=1) & (sigma[:, 0] > 0.0)
        if not ok.any():
            return
        e, ey, s = e[ok], e_yaw[ok], sigma[ok]
        total = self._with_reference(s[:, :2])  # σ of the error against the reference: coverage and NEES
        r = (e / total[:, 0]) ** 2
        self.n += len(r)
        self.inside += int(np.sum(r <= CHI2_2_95))
        self.nees += float(np.sum(r)) / 2.0
        b = np.searchsorted(BINS, s[:, 0])
        self.hist_n += np.bincount(b, minlength=len(self.hist_n))
        self.hist_e += np.bincount(b, weights=e, minlength=len(self.hist_e))
        known = s[:, 1] < FREE_SD
        mag, held = known & (s[:, 1] <= MAG_SD), known & (s[:, 1] > MAG_SD)
        if s.shape[1] > 2:  # the estimator's own state where it says one
            said = np.isfinite(s[:, 2])
            mag = np.where(said, known & (s[:, 2] == HEADING_CORRECTED), mag)
            held = np.where(said, known & (s[:, 2] == HEADING_HELD), held)
        for key, sel in (("mag", mag), ("held", held)):
            if sel.any():
                ry = (ey[sel] / total[sel, 1]) ** 2
                self.yaw[key][0] += int(sel.sum())
                self.yaw[key][1] += int(np.sum(ry <= CHI2_1_95))
                self.yaw_nees += float(np.sum(ry))

    def _with_reference(self, s: NDArray[np.float64]) -> NDArray[np.float64]:
        """σ per axis (inclination, heading) with the reference's own error added in quadrature; as it is when the
        reference is taken as exact (no rounding: the same numbers as without it)."""
        return np.hypot(s, self.reference_sd) if self.reference_sd > 0.0 else s

    def result(self) -> dict[str, Any]:
        """The scores (None where no sample had a σ); keys :data:`KEYS` and ``sigma_hist`` (:func:`histogram`)."""
        if self.n == 0:
            return {**dict.fromkeys(KEYS), "sigma_hist": None}
        bottom, top = decile_errors(self.hist_n, self.hist_e)
        ny = self.yaw["mag"][0] + self.yaw["held"][0]

        def pct(k: str) -> float | None:
            n, inside = self.yaw[k]
            return 100.0 * inside / n if n else None

        return {"nees": self.nees / self.n, "cover95_pct": 100.0 * self.inside / self.n,
                "err_bottom_decile_deg": math.degrees(bottom), "err_top_decile_deg": math.degrees(top),
                "yaw_nees": self.yaw_nees / ny if ny else None, "yaw_cover95_mag_pct": pct("mag"),
                "yaw_cover95_held_pct": pct("held"), "n_yaw_mag": self.yaw["mag"][0],
                "n_yaw_held": self.yaw["held"][0], "sigma_hist": histogram(self.hist_n, self.hist_e)}


def histogram(hist_n: NDArray[np.float64], hist_e: NDArray[np.float64]) -> dict[str, Any]:
    """The σ_i histogram as results.json keeps it: the first non-empty bin ``lo`` of :data:`BINS` (bin ``k`` holds
    σ below ``BINS[k]``), then per bin the samples ``n`` and the sum of their errors ``e_deg``."""
    nz = np.flatnonzero(hist_n)
    lo, hi = int(nz[0]), int(nz[-1]) + 1
    return {"lo": lo, "n": [int(v) for v in hist_n[lo:hi]], "e_deg": [round(math.degrees(v), 6) for v in hist_e[lo:hi]]}


def decile_errors(hist_n: NDArray[np.float64], hist_e: NDArray[np.float64]) -> tuple[float, float]:
    """The mean error of the samples in the bottom and in the top decile of σ, from per-bin counts and error sums
    (a bin split at the decile counts in proportion)."""
    total = float(hist_n.sum())
    k = 0.1 * total

    def lowest(n: NDArray[np.float64], s: NDArray[np.float64]) -> float:
        c = np.cumsum(n)
        full = c <= k
        take = float(s[full].sum())
        j = int(np.argmax(~full)) if (~full).any() else len(n)
        rest = k - (float(c[j - 1]) if j else 0.0)
        if j < len(n) and n[j] > 0:
            take += s[j] * rest / n[j]
        return take / k

    return lowest(hist_n, hist_e), lowest(hist_n[::-1], hist_e[::-1])
