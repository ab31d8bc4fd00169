"""The consensus's two opinions and their timing, on one BROAD trial under one condition: RIANN's inclination RMSE, VQF
on RIANN's rows (moved to RIANN's instant, as the consensus combines it), the consensus, VQF on the samples, the lag
the consensus fitted (:mod:`riann_ros.estimators.consensus_lag`) and what is left of it.

Usage::

    .venv/bin/python bench/consensus_timing.py TRIAL CONDITION      # e.g. 07 rate:50

The trial (``$RIANN_BROAD_DIR`` or ``../shared/datasets/broad``) as recorded, whole (no scenario crop, unlike
``riann-bag-eval``), the condition applied as the evaluator applies it (seed 0). The lag ``τ`` is the least-squares fit
of ``g_V − g_R ≈ −τ (g_R × ω)`` (RIANN's and VQF's gravity directions in the sensor frame, ``ω`` the gyro) over the
whole trial, of VQF as the consensus combines it: what is left of the lag after the consensus's own online fit.
docs/consensus.md, "The two opinions at one instant".
"""

from __future__ import annotations

import sys

import numpy as np

from riann_ros import quaternion as quat
from riann_ros.datasets import read_any
from riann_ros.datasets.broad import broad_files, find_broad_dir
from riann_ros.estimators import create
from riann_ros.estimators.riann.s4a_ensemble import gravity_rows
from riann_ros.evaluation.perturb import parse_condition

BLOCK = 200  # samples per update_batch call (the consensus keeps the two opinions of the last call)


def main(argv: list[str]) -> int:
    if len(argv) != 2:
        print(__doc__, file=sys.stderr)
        return 2
    trial, text = argv
    folder = find_broad_dir()
    if folder is None:
        print("BROAD not found: set RIANN_BROAD_DIR", file=sys.stderr)
        return 2
    rec = read_any(str(next(p for p in broad_files(folder) if p.name.startswith(trial + "_"))))
    cond = parse_condition(text)
    for transform in cond.start([np.random.default_rng(k) for k in range(len(cond.parts))]):
        rec = transform(rec)
    first = int(np.median(np.diff(rec.stamps_ns)))
    dt = np.diff(rec.stamps_ns, prepend=rec.stamps_ns[0] - first) * 1e-9
    consensus = create("consensus")
    n = len(rec)
    q_c = np.empty((n, 4))
    q_r, q_v = [], []
    for a in range(0, n, BLOCK):
        b = min(n, a + BLOCK)
        q_c[a:b] = consensus.update_batch(rec.acc[a:b], rec.gyr[a:b], dt[a:b])
        q_r.append(consensus.last.riann)
        q_v.append(consensus.last.vqf)
    r, v = np.concatenate(q_r), np.concatenate(q_v)
    q_vqf = create("vqf").update_batch(rec.acc, rec.gyr, dt)
    mask = rec.score_mask if rec.score_mask is not None else np.ones(n, dtype=bool)

    def rmse(q: np.ndarray) -> float:
        e = np.degrees(quat.inclination_error(rec.quat_ref[mask], q[mask]))
        return float(np.sqrt(np.nanmean(e * e)))

    g_r = gravity_rows(r)
    turn = np.cross(g_r, rec.gyr)
    left = -float(np.sum((gravity_rows(v) - g_r) * turn) / np.sum(turn * turn))
    print(f"{trial} {text}: RIANN {rmse(r):.3f}, VQF on the rows {rmse(v):.3f}, consensus {rmse(q_c):.3f}, "
          f"VQF {rmse(q_vqf):.3f}; the lag fitted {consensus.lag.tau_s * 1e3:.2f} ms, left {left * 1e3:.2f} ms")
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
