"""The time offset that minimises the inclination error, found for the user (evo's ``--t_offset``; ROS-free).

For one scenario run, :class:`OffsetSearch` scores every estimator with its estimates moved in time against the
reference: the estimate stamped ``t`` against the reference at ``t + τ`` (τ is what ``--t-offset`` would add to
the estimate stamps), for τ on a grid of :data:`GRID` points per input step over ±:data:`STEPS` steps; a parabola
through the best grid point and its neighbours refines τ and the RMSE there. Only samples that are scored at
every τ count (score mask, estimate present, reference present at every shifted time), so the RMSEs of the
offsets compare on the same samples. The reference between its samples is the normalised linear interpolation
of its gravity direction (e_α is the angle between the gravity directions of reference and estimate in the
sensor frame), never across a gap of more than :data:`GAP_STEPS` steps.

The search runs chunk by chunk with a carry of a few samples, so memory does not grow with the sequence.

Why: for a regular stream the sample-time convention (point samples at their stamps, or the means over the
interval before each stamp) cannot be seen from the IMU, and read wrongly it shifts an estimate by half a step;
a reference that is not synchronised with the IMU shifts every estimator alike.

An offset shows only where the reference moves: on a still sensor every offset fits alike, and the best one is
noise. The search therefore also measures how fast the reference's gravity direction turns (RMS over the scored
samples, each against the reference :data:`TURN_SPAN_S` earlier), and :func:`timing_notes` claims an offset only
when that is above the rest detector's threshold and the offset lowers the RMSE clearly. Each note is about one
estimator and reads the same whatever other estimators run.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np
from numpy.typing import NDArray

from riann_ros.constants import NS_PER_S
from riann_ros.evaluation.rest import REST_GYR_DEV_DPS, REST_TAU_S

STEPS = 3  # the search spans ± this many input steps
GRID = 4  # candidate offsets per step (a parabola through the best three refines the best)
GAP_STEPS = 2.5  # the reference is not interpolated across a gap longer than this many steps
HALF_STEP_BAND = (0.3, 0.7)  # |offset| / step in this band: "near half a step"
MIN_GAIN = 0.9  # a note only when the RMSE at the best offset is below this fraction of the RMSE at 0
BLOCK = 4096  # samples scored at a time (memory: a few BLOCK × candidates arrays)
#: s, the span over which the reference's turn is measured: the rest detector's time constant, long enough that a
#: reference's noise (a few hundredths of a degree per sample) is far below the rest threshold's turn over it
TURN_SPAN_S = REST_TAU_S
#: °/s, the RMS turn rate of the reference's gravity direction below which no offset is claimed: the rest
#: detector's gyro threshold (VQF's restThGyr), below which a sensor counts as not rotating
TURN_MIN_DPS = REST_GYR_DEV_DPS


def gravity(q: NDArray[np.float64]) -> NDArray[np.float64]:
    """The world's z axis in the sensor frame (N, 3) of sensor-to-world quaternions w, x, y, z (NaN rows stay)."""
    w, x, y, z = q[:, 0], q[:, 1], q[:, 2], q[:, 3]
    return np.column_stack([2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)])


class _Shifted:
    """The reference's gravity direction at the shifted times ``t[:, None] + taus[None, :]`` (B samples × K
    offsets), ready to be compared with estimates: for each time, the two reference samples around it (at most
    ``gap`` ns apart) and the fraction between them; the dot product with an estimate is then formed from the
    estimate's dot products with the few reference samples near its own time (the interpolated direction is never
    materialised: B × K × 3 arrays would dominate the cost)."""

    def __init__(self, rt: NDArray[np.int64], rg: NDArray[np.float64], t: NDArray[np.int64],
                 taus: NDArray[np.float64], gap: float) -> None:
        times = t[:, None] + taus[None, :]
        self.ok = np.zeros(len(t), bool)
        if len(rt) < 2:
            return
        j = np.clip(np.searchsorted(rt, times, side="right"), 1, len(rt) - 1)
        ta, tb = rt[j - 1], rt[j]
        span = (tb - ta).astype(np.float64)
        inside = (times >= ta) & (times <= tb) & (span <= gap)
        self.ok = np.asarray(inside.all(axis=1), dtype=bool)  # covered at every offset
        f = (times - ta) / span
        lo = (j - 1).min(axis=1)
        self.m = j - 1 - lo[:, None]  # the earlier sample's place in the sample's window
        width = int(self.m.max()) + 2
        self.window = rg[np.minimum(lo[:, None] + np.arange(width)[None, :], len(rt) - 1)]  # (B, W, 3)
        c = np.einsum("bwc,bwc->bw", self.window[:, :-1], self.window[:, 1:])  # neighbours' dot products
        self.wa, self.wb = 1.0 - f, f
        norm2 = self.wa**2 + self.wb**2 + 2 * self.wa * self.wb * np.take_along_axis(c, self.m, axis=1)
        self.inv_norm = 1.0 / np.sqrt(np.maximum(norm2, 1e-300))

    def sq_err_deg(self, g_est: NDArray[np.float64]) -> NDArray[np.float64]:
        """e_α² (deg²) of estimates (B, 3) at every offset: (B, K)."""
        d = np.einsum("bwc,bc->bw", self.window, g_est)
        dot = (self.wa * np.take_along_axis(d, self.m, axis=1) + self.wb * np.take_along_axis(d, self.m + 1, axis=1))
        return np.degrees(np.arccos(np.clip(dot * self.inv_norm, -1.0, 1.0))) ** 2


@dataclass
class Offset:
    """The best offset of one estimator: τ (s, added to the estimate stamps), the e_α RMSE there, and the input step
    it is measured in."""

    offset_s: float
    rmse_deg: float
    step_s: float
    ref_turn_dps: float = math.nan  # RMS turn rate of the reference's gravity direction (°/s, TURN_SPAN_S apart)

    @property
    def steps(self) -> float:
        return self.offset_s / self.step_s


class OffsetSearch:
    """e_α sums of ``n_est`` estimators at the candidate offsets, fed chunk by chunk (:meth:`add`, :meth:`result`).

    ``step_s``: the stream's step (1 / its nominal rate)."""

    def __init__(self, n_est: int, step_s: float, steps: int = STEPS, grid: int = GRID) -> None:
        self.step_ns = step_s * NS_PER_S
        k = np.arange(-steps * grid, steps * grid + 1)
        self.taus = k * self.step_ns / grid  # ns
        self.reach = steps * self.step_ns  # the largest |τ|
        self.gap = GAP_STEPS * self.step_ns
        self.sq = np.zeros((n_est, len(k)))
        self.n = np.zeros(n_est, dtype=np.int64)
        # the reference seen so far (its finite samples, trimmed to what pending samples can still need)
        self.ref_t = np.zeros(0, np.int64)
        self.ref_g = np.zeros((0, 3))
        # samples not yet scored: their stamps, whether they count, and each estimator's gravity direction
        self.pend_t = np.zeros(0, np.int64)
        self.pend_ok = np.zeros(0, bool)
        self.pend_g = [np.zeros((0, 3)) for _ in range(n_est)]
        self.turn = _Turn()

    def add(self, stamps: NDArray[np.int64], quat_ref: NDArray[np.float64] | None, mask: NDArray[np.bool_],
            qs: Sequence[NDArray[np.float64]]) -> None:
        """One chunk: stamps, reference (N, 4) with NaN rows (None: none), score mask and each estimator's estimates
        (N, 4); scores the samples whose shifted times the reference covers with this chunk in."""
        if quat_ref is None or not len(stamps):
            return
        ref_ok = np.isfinite(quat_ref).all(axis=1)
        g_ref = gravity(quat_ref)
        self.turn.add(stamps[ref_ok], g_ref[ref_ok], mask[ref_ok])
        self.ref_t = np.concatenate([self.ref_t, stamps[ref_ok]])
        self.ref_g = np.concatenate([self.ref_g, g_ref[ref_ok]])
        self.pend_t = np.concatenate([self.pend_t, stamps])
        self.pend_ok = np.concatenate([self.pend_ok, mask & ref_ok])
        self.pend_g = [np.concatenate([p, gravity(q)]) for p, q in zip(self.pend_g, qs, strict=True)]
        # a later chunk can still give reference samples after the last stamp seen
        self._score(int(np.searchsorted(self.pend_t, stamps[-1] - self.reach - self.gap, side="left")))

    def _score(self, upto: int) -> None:
        """Score the first ``upto`` pending samples and forget them (and the reference no later sample needs)."""
        if upto <= 0:
            return
        for a in range(0, upto, BLOCK):
            self._score_block(slice(a, min(a + BLOCK, upto)))
        last = self.pend_t[upto - 1]
        self.pend_t, self.pend_ok = self.pend_t[upto:], self.pend_ok[upto:]
        self.pend_g = [p[upto:] for p in self.pend_g]
        first = self.pend_t[0] if len(self.pend_t) else last
        cut = int(np.searchsorted(self.ref_t, first - self.reach - self.gap, side="left"))
        self.ref_t, self.ref_g = self.ref_t[cut:], self.ref_g[cut:]

    def _score_block(self, sl: slice) -> None:
        t, ok = self.pend_t[sl], self.pend_ok[sl]
        if not ok.any():
            return
        idx = np.flatnonzero(ok)
        shifted = _Shifted(self.ref_t, self.ref_g, t[idx], self.taus, self.gap)
        if not shifted.ok.any():
            return
        for j, g_all in enumerate(self.pend_g):
            g_est = g_all[sl][idx]
            use = shifted.ok & np.isfinite(g_est).all(axis=1)
            if not use.any():
                continue
            sq = shifted.sq_err_deg(np.where(use[:, None], g_est, 0.0))
            self.n[j] += int(use.sum())
            self.sq[j] += np.sum(sq[use], axis=0)

    def result(self, j: int) -> Offset | None:
        """The best offset of estimator ``j`` (after the last chunk); None when no sample counted."""
        self._score(len(self.pend_t))
        if self.n[j] == 0:
            return None
        f = self.sq[j]
        k = int(np.argmin(f))
        dk, fk = 0.0, float(f[k])
        if 0 < k < len(f) - 1:
            curv = f[k - 1] - 2 * f[k] + f[k + 1]
            if curv > 0:
                dk = float(np.clip(0.5 * (f[k - 1] - f[k + 1]) / curv, -0.5, 0.5))
                fk = float(f[k] - 0.25 * (f[k - 1] - f[k + 1]) * dk)
        d_tau = self.taus[1] - self.taus[0]
        return Offset(offset_s=float(self.taus[k] + dk * d_tau) * 1e-9, rmse_deg=math.sqrt(max(fk, 0.0) / self.n[j]),
                      step_s=self.step_ns * 1e-9, ref_turn_dps=self.turn.rms_dps)


class _Turn:
    """The RMS rate (°/s) at which the reference's gravity direction turns at the scored samples, each against the
    reference :data:`TURN_SPAN_S` earlier (the latest sample at or before then, if within a quarter span of it),
    fed chunk by chunk with a carry of one span."""

    def __init__(self) -> None:
        self.t = np.zeros(0, np.int64)
        self.g = np.zeros((0, 3))
        self.n = 0
        self.sq = 0.0

    def add(self, t: NDArray[np.int64], g: NDArray[np.float64], scored: NDArray[np.bool_]) -> None:
        span = round(TURN_SPAN_S * NS_PER_S)
        all_t, all_g = np.concatenate([self.t, t]), np.concatenate([self.g, g])
        k = len(self.t) + np.flatnonzero(scored)
        j = np.searchsorted(all_t, all_t[k] - span, side="right") - 1
        ok = (j >= 0) & (all_t[np.maximum(j, 0)] >= all_t[k] - span - span // 4)
        if ok.any():
            dot = np.einsum("ij,ij->i", all_g[k[ok]], all_g[j[ok]])
            rate = np.degrees(np.arccos(np.clip(dot, -1.0, 1.0))) / TURN_SPAN_S
            self.n += len(rate)
            self.sq += float(np.sum(rate**2))
        keep = np.searchsorted(all_t, all_t[-1] - span - span // 4, side="left") if len(all_t) else 0
        self.t, self.g = all_t[keep:], all_g[keep:]

    @property
    def rms_dps(self) -> float:
        return math.sqrt(self.sq / self.n) if self.n else math.nan


def search(stamps: NDArray[np.int64], quat_ref: NDArray[np.float64], mask: NDArray[np.bool_],
           q_est: NDArray[np.float64], step_s: float) -> Offset | None:
    """The best offset of one estimate on a whole recording (the one-chunk case)."""
    s = OffsetSearch(1, step_s)
    s.add(stamps, quat_ref, mask, [q_est])
    return s.result(0)


def is_half_step(offset_steps: float) -> bool:
    return HALF_STEP_BAND[0] <= abs(offset_steps) <= HALF_STEP_BAND[1]


def _ms(s: float) -> str:
    return f"{s * 1e3:+.1f} ms"


def shows_offset(score: Any) -> bool:
    """Whether a row's offset search can show an offset: the reference turns (RMS at least :data:`TURN_MIN_DPS`)
    and the best offset's RMSE is below :data:`MIN_GAIN` of the RMSE at its stamps."""
    turn, best = score.t_offset_ref_turn_dps, score.best_t_offset_rmse_deg
    return (turn is not None and math.isfinite(turn) and turn >= TURN_MIN_DPS and best is not None
            and best < MIN_GAIN * score.rmse_deg)


def _note(where: str, r: Any, steps: int, riann_name: str) -> str | None:
    """The note on one row's best offset (None: nothing to claim); its words depend on that row only."""
    sc = r.score
    off, step = float(sc.best_t_offset_s), float(sc.t_offset_step_s)
    rel = off / step
    if not shows_offset(sc) or abs(rel) < 0.25:
        return None
    head = (f"{where}: {r.estimator} fits the reference best with its estimate moved by {_ms(off)} ({rel:+.2f} steps "
            f"of {step * 1e3:.3g} ms): e_α RMSE {sc.best_t_offset_rmse_deg:.2f}° instead of {r.rmse_deg:.2f}°")
    if abs(rel) >= steps - 0.5 / GRID:
        return head + f", at the edge of the searched offsets (±{steps} steps): it may be larger (--offset-steps)"
    if is_half_step(rel):
        text = (head + ". A shift near half a step is what the driver's sample-time convention gives when it is read "
                "the other way (point samples at their stamps, or means over the interval before each stamp)")
        if r.estimator_name == riann_name:
            text += (": RIANN reads a regular stream below about 180 Hz a quarter step before its stamps "
                     "(sample_delay), between the two, unless its input_model parameter names the convention "
                     "(input_model=points or means; docs/riann.md, stage 1)")
        return text
    return (head + ". An offset that every estimator shows is the reference's and the IMU's stamps being that far "
            "apart (not synchronised), which every score includes; one of this estimator's own is its lag")


def timing_notes(rows: Sequence, steps: int = STEPS, riann_name: str = "riann") -> list[str]:
    """Notes on the best offsets of result rows (:class:`~riann_ros.evaluation.results.ResultRow`), one per row
    whose search shows an offset of at least a quarter step (:func:`shows_offset`): near half a step it points at
    the sample-time convention (RIANN: its ``input_model``), otherwise at unsynchronised stamps or a lag; at the
    edge of the ±``steps`` searched it says the offset may be larger. A note's words depend on its own row only,
    never on which other estimators ran."""
    notes = []
    for r in rows:
        if r.score.best_t_offset_s is None or not r.score.t_offset_step_s:
            continue
        where = f"{r.sequence}, {r.scenario}" + ("" if r.perturbation == "none" else f", {r.perturbation}")
        note = _note(where, r, steps, riann_name)
        if note is not None:
            notes.append(note)
    return notes
