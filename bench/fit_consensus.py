"""Fit the consensus's constants on synthetic sensors of several grades, and show how its σ holds on each (issue 47).

The consensus (riann_ros/estimators/consensus.py) has three fitted constants in VQF's σ (riann_ros/estimators/
vqf_sigma.py: ``K_LAG``, ``K_RATE``, ``K_ACC``; its other terms are physics) and one in the combination
(``RHO_OWN``, the correlation of the two estimators' own errors, kept ≥ 0: estimators on one input do not err
against each other). They are fitted here on the project's synthetic generator
(``riann_ros.datasets.synthetic``: exact reference) over sensor grades that differ in noise density, turn-on bias,
rate and motion (:data:`GRADES`), never on the BROAD trials:

1. VQF's ``K_LAG``, ``K_RATE`` and ``K_ACC`` by maximum likelihood of its 2-D inclination error (``|e|²/σ_V²`` is
   χ²₂), each recording weighted equally;
2. ``RHO_OWN`` by maximum likelihood of the two errors jointly (per axis a 2-D Gaussian of covariance
   ``[[σ_R², c], [c, σ_V²]]``, ``c`` as the consensus models it), RIANN's σ as stage 8 reports it.

Then per grade: the RMSE of RIANN, of VQF on RIANN's rows, of their plain mean and of the consensus, and the 95 %
coverage and NEES per degree of freedom of the σ of RIANN, of VQF (fitted) and of the consensus (as it runs with the
constants in the source: run again after changing them).

    .venv/bin/python bench/fit_consensus.py [--seeds 1] [--duration 60] [--write]

``--write`` keeps the fit and the table in docs/results/consensus_synthetic.json (BENCHMARKS.md's table
``<!-- results:consensus-synthetic -->``, written by bench/results_tables.py).
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path
from typing import NamedTuple

import numpy as np
from scipy.optimize import minimize

from riann_ros.datasets.synthetic import generate
from riann_ros.estimators.consensus import RHO_OWN, ConsensusEstimator
from riann_ros.estimators.riann.s4a_ensemble import gravity_rows
from riann_ros.estimators.riann.s8_uncertainty import K_BIAS
from riann_ros.estimators.vqf_sigma import K_ACC, K_LAG, K_RATE

CHI2_2_95 = 5.991


class Grade(NamedTuple):
    rate: float  # Hz
    gyr_noise: float  # rad/s per sample
    acc_noise: float  # m/s² per sample
    bias: float  # rad/s, turn-on gyro bias magnitude


#: sensor grades of the generator: a tactical-grade unit, the generator's defaults, a consumer MEMS at 100 Hz with a
#: 3 °/s turn-on bias, a noisy low-cost MEMS at 400 Hz, and a slow 50 Hz stream
GRADES = {
    "tactical 200 Hz": Grade(200.0, 0.001, 0.01, 0.005),
    "default 200 Hz": Grade(200.0, 0.004, 0.03, 0.01),
    "consumer 100 Hz": Grade(100.0, 0.01, 0.08, 0.05),
    "low-cost 400 Hz": Grade(400.0, 0.02, 0.15, 0.03),
    "slow 50 Hz": Grade(50.0, 0.004, 0.03, 0.02),
}
MOTIONS = ("combined", "rotation", "translation")


def tangent_error(q_ref: np.ndarray, q: np.ndarray) -> np.ndarray:
    """The inclination error as a vector (N, 3): ``g_ref × g``, the tilt's axis times the sine of its angle."""
    return np.cross(gravity_rows(q_ref), gravity_rows(q))


def record(grade: Grade, motion: str, seed: int, duration: float) -> dict[str, np.ndarray]:
    """One synthetic recording through the consensus: per scored sample the three error vectors, the three σ, VQF's
    σ terms and RIANN's stage-8 features."""
    rec = generate(rate=grade.rate, duration=duration, seed=seed, motion=motion, bias=grade.bias,
                   gyr_noise=grade.gyr_noise, acc_noise=grade.acc_noise)
    est = ConsensusEstimator()
    q = est.update_batch(rec.acc, rec.gyr, np.full(len(rec.acc), 1.0 / grade.rate))
    m = np.asarray(rec.score_mask, dtype=bool)
    assert rec.quat_ref is not None
    ref = rec.quat_ref[m]
    op = est.last
    mean = gravity_rows(op.riann) + gravity_rows(op.vqf)
    return {"e_r": tangent_error(ref, op.riann[m]), "e_v": tangent_error(ref, op.vqf[m]),
            "e_c": tangent_error(ref, q[m]), "e_m": np.cross(gravity_rows(ref), mean[m] / np.linalg.norm(
                mean[m], axis=1, keepdims=True)),
            "s_r": est.riann.last.sigma_rad[m, 0], "s_c": est.sigma(np.zeros(len(q), dtype=bool))[m, 0],
            "t": op.vqf_terms[m], "f": est.riann.last.features[m]}


Ks = tuple[float, float, float]


def vqf_var(t: np.ndarray, k: Ks) -> np.ndarray:
    """σ_V² with the constants ``k`` = (K_LAG, K_RATE, K_ACC) from the terms computed with the source's."""
    return (t[:, 0] + t[:, 1] * (k[0] / K_LAG) ** 2 + t[:, 2] * (k[1] / K_RATE) ** 2 + t[:, 3] * (k[2] / K_ACC) ** 2
            + t[:, 4])


def fit_vqf(data: list[dict[str, np.ndarray]]) -> Ks:
    def nll(logk: np.ndarray) -> float:
        k = (float(np.exp(logk[0])), float(np.exp(logk[1])), float(np.exp(logk[2])))
        tot = 0.0
        for d in data:
            v = vqf_var(d["t"], k)
            e2 = np.sum(d["e_v"] ** 2, axis=1)
            tot += float(np.mean(np.log(v) + e2 / (2.0 * v)))
        return tot

    r = minimize(nll, np.log([K_LAG, K_RATE, K_ACC]), method="Nelder-Mead")
    return float(np.exp(r.x[0])), float(np.exp(r.x[1])), float(np.exp(r.x[2]))


def covariance(d: dict[str, np.ndarray], k: Ks, rho: float) -> tuple[np.ndarray, ...]:
    """Per sample σ_R², σ_V² and their covariance as the consensus models it."""
    t = d["t"]
    vr, vv = d["s_r"] ** 2, vqf_var(t, k)
    lag_r = (K_BIAS * d["f"][:, 3]) ** 2
    own_r = np.maximum(vr - t[:, 0] - lag_r, 0.0)
    lag_v = t[:, 1] * (k[0] / K_LAG) ** 2
    own_v = np.maximum(vv - t[:, 0] - lag_v, 0.0)
    return vr, vv, t[:, 0] + np.sqrt(lag_r * lag_v) + rho * np.sqrt(own_r * own_v)


def fit_rho(data: list[dict[str, np.ndarray]], k: Ks) -> float:
    """The maximum-likelihood ρ of the own errors on a grid from −0.5 (printed as found; the source keeps it ≥ 0)."""
    grid = np.linspace(-0.5, 0.9, 29)
    best, arg = np.inf, 0.0
    for rho in grid:
        tot = 0.0
        for d in data:
            vr, vv, c = covariance(d, k, float(rho))
            det = np.maximum(vr * vv - c * c, 1e-30)
            er2, ev2 = np.sum(d["e_r"] ** 2, axis=1), np.sum(d["e_v"] ** 2, axis=1)
            erv = np.sum(d["e_r"] * d["e_v"], axis=1)
            tot += float(np.mean(np.log(det) + 0.5 * (vv * er2 - 2 * c * erv + vr * ev2) / det))
        if tot < best:
            best, arg = tot, float(rho)
    return arg


def scores(e: np.ndarray, s: np.ndarray) -> tuple[float, float]:
    """The σ's 95 % coverage (%) and NEES per degree of freedom of 2-D errors ``e`` (rad)."""
    r = np.sum(e * e, axis=1) / (s * s)
    return float(100 * np.mean(r <= CHI2_2_95)), float(np.mean(r) / 2)


def table(rows: list[dict]) -> str:
    """Per grade: RMSE of RIANN, VQF on its rows, their plain mean and the consensus; each σ's coverage / NEES."""
    def cell(v: list[float]) -> str:
        return f"{v[0]:.1f} % / {v[1]:.2f}"

    lines = ["| grade | RMSE RIANN | VQF (rows) | mean | consensus | σ_R cov / NEES | σ_V (fitted) | σ consensus |",
             "|---|---:|---:|---:|---:|---:|---:|---:|"]
    lines += [f"| {r['grade']} | {r['rmse_r']:.2f} | {r['rmse_v']:.2f} | {r['rmse_m']:.2f} | {r['rmse_c']:.2f} | "
              f"{cell(r['riann'])} | {cell(r['vqf'])} | {cell(r['consensus'])} |" for r in rows]
    return "\n".join(lines)


def rmse(e: np.ndarray) -> float:
    return float(np.degrees(np.sqrt(np.mean(np.sum(e * e, axis=1)))))


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--seeds", type=int, default=1)
    ap.add_argument("--duration", type=float, default=60.0)
    ap.add_argument("--write", action="store_true", help="keep the table in docs/results/consensus_synthetic.json")
    args = ap.parse_args()
    by_grade: dict[str, list[dict[str, np.ndarray]]] = {}
    for name, grade in GRADES.items():
        for motion in MOTIONS:
            for seed in range(1, args.seeds + 1):
                by_grade.setdefault(name, []).append(record(grade, motion, seed, args.duration))
        print(f"{name}: done", file=sys.stderr)
    data = [d for v in by_grade.values() for d in v]
    k = fit_vqf(data)
    rho = fit_rho(data, k)
    print(f"fitted on {len(data)} synthetic recordings: K_LAG {k[0]:.3f} s, K_RATE {k[1]:.5f} s, K_ACC {k[2]:.4f}, "
          f"RHO_OWN {rho:+.2f} (in the source: {K_LAG}, {K_RATE}, {K_ACC}, {RHO_OWN:+.2f})")
    rows = []
    for name, ds in by_grade.items():
        cat = {key: np.concatenate([d[key] for d in ds]) for key in ds[0]}
        sv = np.sqrt(vqf_var(cat["t"], k))
        rows.append({"grade": name, **{f"rmse_{e}": float(np.mean([rmse(d[f"e_{e}"]) for d in ds])) for e in "rvmc"},
                     "riann": scores(cat["e_r"], cat["s_r"]), "vqf": scores(cat["e_v"], sv),
                     "consensus": scores(cat["e_c"], cat["s_c"])})
    print("\n" + table(rows))
    if args.write:
        out = Path(__file__).resolve().parents[1] / "docs" / "results" / "consensus_synthetic.json"
        out.write_text(json.dumps({"command": f"bench/fit_consensus.py --seeds {args.seeds} --duration "
                                   f"{args.duration:g} --write", "fit": [*k, rho], "rows": rows}, indent=1) + "\n")
        print(f"wrote {out}", file=sys.stderr)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
