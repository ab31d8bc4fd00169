"""Scoring, the paper's way (eq. 3), accumulated chunk by chunk (ROS-free).

Per sample e_α = 2·arccos(√(w² + z²)) of q_err = q_ref ⊗ q_est⁻¹ (heading ignored); per sequence the
RMSE over the scored samples: score mask ∩ reference present ∩ estimate present (samples the input gate
rejected have no estimate and are counted as ``n_unestimated``), and beside it evo ape's statistics of the
per-sample errors: mean, median, std, min and max (:data:`STATS`). Heading and total-angle errors are
optional extra columns with the same statistics, and for 6D runs the heading drift: the heading error after
aligning the estimate's heading with the reference's at the first scored sample (:func:`yaw_aligned`).
:class:`Accumulator` keeps running sums (and, for the median,
a histogram of log-spaced bins, :class:`ErrorStats`), so a bag of any length is scored in bounded memory;
:func:`score` is the one-chunk case. With the estimator's σ per sample the uncertainty is scored too (NEES,
95 % coverage, sharpness: :mod:`riann_ros.evaluation.uncertainty`).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

import numpy as np
from numpy.typing import NDArray

from riann_ros import quaternion as quat
from riann_ros.evaluation.errors import EvalError
from riann_ros.evaluation.uncertainty import UncertaintySums
from riann_ros.recording import Recording

STATS = ("rmse", "mean", "median", "std", "min", "max")  # evo ape's statistics, per sequence
ERRORS = ("inclination", "heading", "total", "heading_drift")
# the median comes from a histogram of bins whose edges grow by this factor (from HIST_LO_DEG up to 360°): it is
# the geometric centre of its bin, so within ±0.1 % of the exact median (clamped to [min, max])
HIST_RATIO = 1.002
HIST_LO_DEG = 1e-6
_LOG_RATIO = math.log(HIST_RATIO)
HIST_BINS = math.ceil(math.log(360.0 / HIST_LO_DEG) / _LOG_RATIO) + 2


def stat_field(error: str, stat: str) -> str:
    """The results.json / results.csv column of a statistic: ``rmse_deg``, ``max_err_deg``, ``mean_err_deg``, …
    for the inclination e_α; ``heading_rmse_deg``, ``total_median_deg``, ``heading_drift_rmse_deg``, … for the
    heading, total and heading-drift errors."""
    if error not in ERRORS or stat not in STATS:
        raise ValueError(f"unknown error statistic {error} {stat}")
    if error == "inclination":
        return "rmse_deg" if stat == "rmse" else f"{stat}_err_deg"
    return f"{error}_{stat}_deg"


class ErrorStats:
    """Running statistics of per-sample errors (degrees): count, sum, sum of squares, min, max, and a histogram of
    log-spaced bins for the median. Adding chunks in any split gives the same result."""

    def __init__(self) -> None:
        self.n = 0
        self.sum = self.sq = 0.0
        self.lo, self.hi = math.inf, -math.inf
        self.hist: NDArray[np.int64] | None = None

    def add(self, e_deg: NDArray[np.float64]) -> None:
        if not len(e_deg):
            return
        self.n += len(e_deg)
        self.sum += float(np.sum(e_deg))
        self.sq += float(np.sum(e_deg**2))
        self.lo = min(self.lo, float(e_deg.min()))
        self.hi = max(self.hi, float(e_deg.max()))
        idx = np.zeros(len(e_deg), dtype=np.int64)
        pos = e_deg > HIST_LO_DEG
        idx[pos] = np.floor(np.log(e_deg[pos] / HIST_LO_DEG) / _LOG_RATIO).astype(np.int64) + 1
        counts = np.bincount(np.clip(idx, 0, HIST_BINS - 1), minlength=HIST_BINS)
        self.hist = counts if self.hist is None else self.hist + counts

    def _order_stat(self, k: int, cum: NDArray[np.int64]) -> float:
        """The k-th smallest error (0-based), as the geometric centre of its bin."""
        b = int(np.searchsorted(cum, k, side="right"))
        centre = HIST_LO_DEG / 2 if b == 0 else HIST_LO_DEG * HIST_RATIO ** (b - 0.5)
        return min(max(centre, self.lo), self.hi)

    def summary(self) -> dict[str, float]:
        """rmse, mean, median, std (population, as numpy and evo), min, max."""
        if self.n == 0 or self.hist is None:
            return {s: float("nan") for s in STATS}
        mean = self.sum / self.n
        cum = np.cumsum(self.hist)
        k = self.n // 2
        median = self._order_stat(k, cum) if self.n % 2 else 0.5 * (self._order_stat(k - 1, cum)
                                                                     + self._order_stat(k, cum))
        return {"rmse": math.sqrt(self.sq / self.n), "mean": mean, "median": median,
                "std": math.sqrt(max(self.sq / self.n - mean * mean, 0.0)), "min": self.lo, "max": self.hi}


@dataclass
class Score:
    """The scores of one estimator on one sequence: the inclination e_α's RMSE and statistics; heading and total
    error statistics when scored; the time offset that minimises e_α (:mod:`~riann_ros.evaluation.timing`).
    Fields that are None were not scored (or come from an older results.json)."""

    n_samples: int
    n_scored: int
    n_unestimated: int
    rmse_deg: float
    max_err_deg: float
    heading_rmse_deg: float | None = None
    total_rmse_deg: float | None = None
    mean_err_deg: float | None = None
    median_err_deg: float | None = None
    std_err_deg: float | None = None
    min_err_deg: float | None = None
    heading_mean_deg: float | None = None
    heading_median_deg: float | None = None
    heading_std_deg: float | None = None
    heading_min_deg: float | None = None
    heading_max_deg: float | None = None
    total_mean_deg: float | None = None
    total_median_deg: float | None = None
    total_std_deg: float | None = None
    total_min_deg: float | None = None
    total_max_deg: float | None = None
    # the heading error after aligning the start heading (6D runs with --heading: heading drift)
    heading_drift_rmse_deg: float | None = None
    heading_drift_mean_deg: float | None = None
    heading_drift_median_deg: float | None = None
    heading_drift_std_deg: float | None = None
    heading_drift_min_deg: float | None = None
    heading_drift_max_deg: float | None = None
    best_t_offset_s: float | None = None  # added to the estimate stamps, the e_α RMSE is smallest (timing)
    best_t_offset_rmse_deg: float | None = None  # the e_α RMSE there
    t_offset_step_s: float | None = None  # the stream's step the offset search is measured in
    # RMS rate (°/s) at which the reference's gravity direction turns over the offset search's samples: an offset
    # shows only where the reference moves (offsets.timing_notes)
    t_offset_ref_turn_dps: float | None = None

    def stat(self, error: str, stat: str) -> float | None:
        """One statistic (:func:`stat_field`), None when not scored."""
        v = getattr(self, stat_field(error, stat))
        return None if v is None else float(v)

    # the reported uncertainty (riann_ros.evaluation.uncertainty; None: the estimator reported none)
    nees: float | None = None
    cover95_pct: float | None = None
    err_bottom_decile_deg: float | None = None
    err_top_decile_deg: float | None = None
    yaw_nees: float | None = None
    yaw_cover95_mag_pct: float | None = None
    yaw_cover95_held_pct: float | None = None
    n_yaw_mag: int | None = None
    n_yaw_held: int | None = None
    sigma_hist: dict[str, Any] | None = None  # the σ histogram (uncertainty.histogram): results.json and the plot

    @property
    def sharpness(self) -> float | None:
        """The mean error in the top decile of σ over that in the bottom decile."""
        if self.err_top_decile_deg is None or not self.err_bottom_decile_deg:
            return None
        return self.err_top_decile_deg / self.err_bottom_decile_deg


class Accumulator:
    """Running sums for the scores over the chunks of one scenario × estimator run."""

    def __init__(self, with_heading: bool = False, reference_sd_deg: float = 0.0) -> None:
        """``reference_sd_deg``: the reference's own error per axis (1σ, °), added to the estimator's σ where the
        uncertainty is scored (:class:`~riann_ros.evaluation.uncertainty.UncertaintySums`)."""
        self.with_heading = with_heading
        self.n = self.n_scored = self.n_unest = self.n_base = 0
        self.errors = {e: ErrorStats() for e in ERRORS}
        self.unc = UncertaintySums(math.radians(reference_sd_deg))
        self.yaw0: float | None = None  # rad, the heading offset at the first scored sample (heading drift)

    def add(self, quat_ref: NDArray[np.float64] | None, mask: NDArray[np.bool_], q: NDArray[np.float64],
            sigma: NDArray[np.float64] | None = None) -> None:
        """One chunk: reference (N, 4) with NaN rows (None: no reference), score mask, estimates (N, 4), and the
        estimator's σ (N, 2) when it reports one, (N, 3) with its heading state (:mod:`.uncertainty`)."""
        self.n += len(q)
        if quat_ref is None:
            return
        ref_ok = np.isfinite(quat_ref).all(axis=1)
        est_ok = np.isfinite(q).all(axis=1)
        base = mask & ref_ok
        valid = base & est_ok
        self.n_base += int(base.sum())
        self.n_scored += int(valid.sum())
        self.n_unest += int((base & ~est_ok).sum())
        if valid.any():
            qt, qe = quat_ref[valid], q[valid]
            e = quat.inclination_error(qt, qe)
            eh = quat.heading_error(qt, qe)
            self.errors["inclination"].add(np.degrees(e))
            self.errors["heading"].add(np.degrees(eh))  # reported for 9D runs, --heading
            self.errors["total"].add(np.degrees(quat.total_error(qt, qe)))
            if self.yaw0 is None:
                self.yaw0 = heading_offset(qt[:1], qe[:1])[0]
            self.errors["heading_drift"].add(np.degrees(quat.heading_error(qt, yaw_aligned(qe, self.yaw0))))
            if sigma is not None:
                self.unc.add(e, eh, sigma[valid])

    def result(self, with_heading: bool | None = None, drift: bool = False) -> Score:
        """The scores; heading and total error when ``with_heading`` (default: as constructed); the heading drift
        when ``drift`` too (6D runs: their heading starts wherever the estimator puts it)."""
        heading = self.with_heading if with_heading is None else with_heading
        if self.n_base == 0:
            raise EvalError("no scored samples (score mask ∩ reference present is empty)")
        if self.n_scored == 0:
            raise EvalError("the estimator gave no output on any scored sample")

        wanted = ["inclination", *(["heading", "total"] if heading else []),
                  *(["heading_drift"] if heading and drift else [])]
        stats: dict[str, Any] = {stat_field(err, st): v for err in wanted
                                 for st, v in self.errors[err].summary().items()}
        return Score(n_samples=self.n, n_scored=self.n_scored, n_unestimated=self.n_unest, **stats,
                     **self.unc.result())


def score(rec: Recording, q_est: NDArray[np.float64], with_heading: bool = False) -> Score:
    """The scores of estimates ``q_est`` (N, 4) on a whole recording."""
    if rec.quat_ref is None:
        raise EvalError("no reference orientation (nothing to score against)")
    acc = Accumulator(with_heading)
    acc.add(rec.quat_ref, np.asarray(rec.score_mask, dtype=bool), np.asarray(q_est, dtype=float))
    return acc.result()


def heading_offset(q_ref: NDArray[np.float64], q_est: NDArray[np.float64]) -> NDArray[np.float64]:
    """The signed heading (rad) of ``q_ref ⊗ q_est⁻¹`` per sample: the rotation about world z that brings the
    estimate's heading onto the reference's (what :func:`riann_ros.quaternion.heading_error` measures, with its
    sign)."""
    qe = quat.multiply(q_ref, quat.conjugate(q_est))
    return 2.0 * np.arctan2(qe[..., 3], qe[..., 0])


def yaw_aligned(q_est: NDArray[np.float64], yaw: float) -> NDArray[np.float64]:
    """The estimates rotated about world z by ``yaw`` (rad): ``R_z(yaw) ⊗ q_est``. With ``yaw`` the heading offset
    at the first scored sample (:func:`heading_offset`) the heading error starts at 0 and the inclination and
    its error are unchanged: what is left is the drift since then."""
    half = 0.5 * yaw
    rz = np.array([math.cos(half), 0.0, 0.0, math.sin(half)])
    return quat.multiply(rz, q_est)


def error_deg(quat_ref: NDArray[np.float64], q_est: NDArray[np.float64]) -> NDArray[np.float64]:
    """e_α in degrees per sample (NaN where the reference or the estimate is missing)."""
    return np.degrees(quat.inclination_error(quat_ref, q_est))


def roll_pitch_deg(q: NDArray[np.float64]) -> NDArray[np.float64]:
    """Roll and pitch (°, (N, 2)) of sensor-to-world quaternions w, x, y, z: the Z-Y-X (yaw-pitch-roll) Euler
    angles, which do not depend on the heading, so estimators with different headings compare (NaN rows stay)."""
    q = np.asarray(q, dtype=float)
    w, x, y, z = q[:, 0], q[:, 1], q[:, 2], q[:, 3]
    roll = np.arctan2(2 * (w * x + y * z), 1 - 2 * (x * x + y * y))
    pitch = np.arcsin(np.clip(2 * (w * y - z * x), -1.0, 1.0))
    return np.degrees(np.column_stack([roll, pitch]))


def heading_deg(q: NDArray[np.float64]) -> NDArray[np.float64]:
    """The heading (°, (N,)) of sensor-to-world quaternions: the Z-Y-X Euler yaw beside :func:`roll_pitch_deg`'s roll
    and pitch, in (−180°, 180°]; a 6D estimator's starts wherever it initialises (NaN rows stay)."""
    q = np.asarray(q, dtype=float)
    w, x, y, z = q[:, 0], q[:, 1], q[:, 2], q[:, 3]
    return np.degrees(np.arctan2(2 * (w * z + x * y), 1 - 2 * (y * y + z * z)))
