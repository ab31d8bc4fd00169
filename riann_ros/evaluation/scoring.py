"""Scoring, the paper's way (eq. 3), accumulated chunk by chunk (ROS-free).

Per sample e_α = 2·arccos(√(w² + z²)) of q_err = q_ref ⊗ q_est⁻¹ (heading ignored); per sequence the
RMSE over the scored samples: score mask ∩ reference present ∩ estimate present (samples the input gate
rejected have no estimate and are counted as ``n_unestimated``). Heading and total-angle RMSEs are
optional extra columns. With the estimator's σ per sample the uncertainty is scored too (NEES, 95 % coverage,
sharpness: :mod:`riann_ros.evaluation.uncertainty`). :class:`Accumulator` keeps running sums, so a bag of any
length is scored in bounded memory; :func:`score` is the one-chunk case.
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


@dataclass
class Score:
    """The scores of one estimator on one sequence."""

    n_samples: int
    n_scored: int
    n_unestimated: int
    rmse_deg: float
    max_err_deg: float
    heading_rmse_deg: float | None = None
    total_rmse_deg: float | None = None
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
    """Running sums for the RMSE over the chunks of one scenario × estimator run."""

    def __init__(self, with_heading: bool = False) -> None:
        self.with_heading = with_heading
        self.n = self.n_scored = self.n_unest = self.n_base = 0
        self.sq = self.sq_heading = self.sq_total = 0.0
        self.max_e = -math.inf
        self.unc = UncertaintySums()

    def add(self, quat_ref: NDArray[np.float64] | None, mask: NDArray[np.bool_], q: NDArray[np.float64],
            sigma: NDArray[np.float64] | None = None) -> None:
        """One chunk: reference (N, 4) with NaN rows (None: no reference), score mask, estimates (N, 4), and the
        estimator's σ (N, 2) when it reports one."""
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
            self.sq += float(np.sum(e**2))
            self.max_e = max(self.max_e, float(e.max()))
            eh = quat.heading_error(qt, qe)
            self.sq_heading += float(np.sum(eh**2))  # reported for 9D runs, --heading
            self.sq_total += float(np.sum(quat.total_error(qt, qe) ** 2))
            if sigma is not None:
                self.unc.add(e, eh, sigma[valid])

    def result(self, with_heading: bool | None = None) -> Score:
        """The scores; heading and total error when ``with_heading`` (default: as constructed)."""
        heading = self.with_heading if with_heading is None else with_heading
        if self.n_base == 0:
            raise EvalError("no scored samples (score mask ∩ reference present is empty)")
        if self.n_scored == 0:
            raise EvalError("the estimator gave no output on any scored sample")

        def rms(sq: float) -> float:
            return float(np.degrees(np.sqrt(sq / self.n_scored)))

        return Score(
            n_samples=self.n,
            n_scored=self.n_scored,
            n_unestimated=self.n_unest,
            rmse_deg=rms(self.sq),
            max_err_deg=float(np.degrees(self.max_e)),
            heading_rmse_deg=rms(self.sq_heading) if heading else None,
            total_rmse_deg=rms(self.sq_total) if heading else None,
            **self.unc.result(),
        )


def score(rec: Recording, q_est: NDArray[np.float64], with_heading: bool = False) -> Score:
    """The scores of estimates ``q_est`` (N, 4) on a whole recording."""
    if rec.quat_ref is None:
        raise EvalError("no reference orientation (nothing to score against)")
    acc = Accumulator(with_heading)
    acc.add(rec.quat_ref, np.asarray(rec.score_mask, dtype=bool), np.asarray(q_est, dtype=float))
    return acc.result()


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
