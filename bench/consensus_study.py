"""How RIANN's and VQF's inclination errors relate on the BROAD trials: what a consensus of the two can gain (issue 47).

Runs each estimator over each trial as ``riann-bag-eval -s as-recorded --use-mag false`` runs it (6D, through the
node's :class:`~riann_ros.stream.EstimatorStream`, the trial's rate as ``nominal_rate``) and prints, over the scored
samples:

1. per trial and pooled: the RMSE of RIANN, of VQF, of their plain mean (the two gravity directions averaged), of the
   mean where they agree within 2° (else RIANN's), and of every other estimator asked (``--estimators``);
2. the correlation of their errors: per axis (roll and pitch errors, Pearson, and the uncentred
   ``E[e_R e_V] / √(E[e_R²] E[e_V²])`` that decides a combination's mean square error) and of the error vectors
   (``e = g_ref × g``, the tilt error's axis times the sine of its angle: ``ρ = E[e_R·e_V] / √(E|e_R|² E|e_V|²)``),
   and the weight on RIANN that would have minimised the pooled mean square error (in hindsight: not a constant any
   estimator uses);
3. how each estimator's reported σ (``sigma()``, per axis) relates to its errors: 95 % coverage (``e²/σ² ≤ 5.991``),
   NEES per degree of freedom, Spearman's rank correlation of σ and the error, and the mean error in the top decile of
   σ over the bottom decile; and the two estimators' disagreement ``d`` (the angle between their gravity directions)
   against what their σ and the measured ρ say it should be (``E[d²] = 2(σ_R² + σ_V² − 2ρσ_Rσ_V)``).

    .venv/bin/python bench/consensus_study.py [--trials 01,21] [--estimators riann,vqf,consensus] [--cache DIR]

``--cache`` keeps each run's attitudes and σ between calls (derived from BROAD: keep it outside the repository).
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

import numpy as np

from riann_ros.datasets.broad import broad_files, find_broad_dir, read_broad
from riann_ros.estimators import create
from riann_ros.evaluation.scoring import roll_pitch_deg
from riann_ros.gate import GateConfig
from riann_ros.magcal.input import MagConfig
from riann_ros.recording import Recording
from riann_ros.stream import EstimatorStream

CHI2_2_95 = 5.991  # χ²₂(0.95)
AGREE_DEG = 2.0  # the "average only where they agree within 2°"


def gravity(q: np.ndarray) -> np.ndarray:
    """World up in the sensor frame, (N, 3), of sensor-to-world quaternions (N, 4)."""
    w, x, y, z = q[:, 0], q[:, 1], q[:, 2], q[:, 3]
    return np.column_stack([2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)])


def angle(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """The angle (rad) between unit row vectors."""
    return np.arctan2(np.linalg.norm(np.cross(a, b), axis=1), np.sum(a * b, axis=1))


def run(rec: Recording, spec: str) -> tuple[np.ndarray, np.ndarray]:
    """The estimator ``spec`` (``name`` or ``name:key=value,...``) over ``rec`` as the evaluator runs it, 6D: attitudes
    (N, 4), NaN where rejected, and the inclination σ per axis (N,) in rad."""
    name, _, rest = spec.partition(":")
    params = dict(kv.split("=", 1) for kv in rest.split(",") if kv)
    est = create(name, **{k: _value(v) for k, v in params.items()})
    rate = 1e9 / float(np.median(np.diff(rec.stamps_ns)))
    stream = EstimatorStream(est, GateConfig.for_rate(rate), MagConfig(use_mag="false"))
    q, _ = stream.process_batch(rec.stamps_ns, rec.acc, rec.gyr, None)
    return q, stream.batch_sigma[:, 0].copy()


def _value(text: str) -> object:
    low = text.lower()
    if low in ("true", "false"):
        return low == "true"
    try:
        return float(text) if any(c in text for c in ".e") else int(text)
    except ValueError:
        return text


def trial(path: Path, specs: list[str], cache: Path | None) -> dict[str, np.ndarray]:
    """The reference and each estimator's attitudes and σ on the scored samples of one trial."""
    out: dict[str, np.ndarray] = {}
    rec: Recording | None = None
    for spec in specs:
        c = cache / f"{path.stem}__{spec.replace(':', '_').replace('=', '-')}.npz" if cache else None
        if c is not None and c.exists():
            z = np.load(c)
            q, s, ref, mask = z["q"], z["s"], z["ref"], z["mask"]
        else:
            rec = rec or read_broad(path)
            q, s = run(rec, spec)
            assert rec.quat_ref is not None
            ref, mask = rec.quat_ref, np.asarray(rec.score_mask, dtype=bool)
            if c is not None:
                np.savez(c, q=q, s=s, ref=ref, mask=mask)
        out[spec], out[spec + "/s"] = q, s
        out["ref"], out["mask"] = ref, mask
    ok = out["mask"] & np.isfinite(out["ref"]).all(axis=1)
    for spec in specs:
        ok &= np.isfinite(out[spec]).all(axis=1) & np.isfinite(out[spec + "/s"])
    return {k: v[ok] for k, v in out.items() if k != "mask"}


def rmse_deg(e: np.ndarray) -> float:
    return float(np.degrees(np.sqrt(np.mean(e * e))))


def errors(d: dict[str, np.ndarray], specs: list[str]) -> dict[str, np.ndarray]:
    """Per sample: each estimator's inclination error (rad) and error vector, the plain mean's and the 2°-agreement
    mean's errors, the per-axis (roll, pitch) errors of RIANN and VQF (deg) and their disagreement (rad)."""
    gr = gravity(d["ref"])
    out: dict[str, np.ndarray] = {}
    g = {s: gravity(d[s]) for s in specs}
    for s in specs:
        out[s] = angle(gr, g[s])
        out[s + "/v"] = np.cross(gr, g[s])
    r, v = g["riann"], g["vqf"]
    m = r + v
    m /= np.linalg.norm(m, axis=1, keepdims=True)
    out["mean"] = angle(gr, m)
    dis = angle(r, v)
    out["d"] = dis
    out["agree"] = np.where(np.degrees(dis) < AGREE_DEG, out["mean"], out["riann"])
    ref_rp = roll_pitch_deg(d["ref"])
    for s in ("riann", "vqf"):
        rp = roll_pitch_deg(d[s]) - ref_rp
        out[s + "/rp"] = (rp + 180.0) % 360.0 - 180.0
    return out


def correlations(e: dict[str, np.ndarray]) -> dict[str, float]:
    """The correlations of RIANN's and VQF's errors (module docstring, 2)."""
    out = {}
    for j, axis in enumerate(("roll", "pitch")):
        a, b = e["riann/rp"][:, j], e["vqf/rp"][:, j]
        out[f"{axis} pearson"] = float(np.corrcoef(a, b)[0, 1])
        out[f"{axis} uncentred"] = float(np.mean(a * b) / np.sqrt(np.mean(a * a) * np.mean(b * b)))
    a, b = e["riann/v"], e["vqf/v"]
    sab, saa, sbb = np.mean(np.sum(a * b, axis=1)), np.mean(np.sum(a * a, axis=1)), np.mean(np.sum(b * b, axis=1))
    out["vector"] = float(sab / np.sqrt(saa * sbb))
    out["w_riann (hindsight)"] = float((sbb - sab) / (saa + sbb - 2 * sab))
    return out


def sigma_stats(e: np.ndarray, s: np.ndarray) -> tuple[float, float, float, float]:
    """95 % coverage (%), NEES per DOF, Spearman's rank correlation of σ and e, and the top / bottom decile error."""
    r = e * e / (s * s)
    rank = np.nan
    ratio = np.nan
    if np.ptp(s) > 0:
        rank = float(np.corrcoef(np.argsort(np.argsort(s)), np.argsort(np.argsort(e)))[0, 1])
        lo, hi = np.quantile(s, [0.1, 0.9])
        if hi > lo:
            ratio = float(e[s >= hi].mean() / e[s <= lo].mean())
    return float(100 * np.mean(r <= CHI2_2_95)), float(np.mean(r) / 2), rank, ratio


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--trials", default="", help="comma-separated trial numbers (default: all)")
    ap.add_argument("--estimators", default="riann,vqf", help="estimator specs beside riann and vqf (name:k=v)")
    ap.add_argument("--cache", type=Path, default=None)
    args = ap.parse_args()
    d = find_broad_dir()
    if d is None:
        print("BROAD not found (set RIANN_BROAD_DIR)", file=sys.stderr)
        return 1
    specs = list(dict.fromkeys(["riann", "vqf", *(s for s in args.estimators.split(",") if s)]))
    want = {t for t in args.trials.split(",") if t}
    if args.cache:
        args.cache.mkdir(parents=True, exist_ok=True)
    names = [*specs, "mean", "agree"]
    pooled: dict[str, list[np.ndarray]] = {}
    print("| trial | " + " | ".join(names) + " | ρ vector | ρ roll | ρ pitch |")
    print("|---|" + "---:|" * (len(names) + 3))
    for p in broad_files(d):
        if want and p.stem[:2] not in want:
            continue
        data = trial(p, specs, args.cache)
        e = errors(data, specs)
        for k, v in e.items():
            pooled.setdefault(k, []).append(v)
        for s in specs:
            pooled.setdefault(s + "/s", []).append(data[s + "/s"])
        c = correlations(e)
        print(f"| {p.stem[:2]} | " + " | ".join(f"{rmse_deg(e[n]):.2f}" for n in names)
              + f" | {c['vector']:+.2f} | {c['roll pearson']:+.2f} | {c['pitch pearson']:+.2f} |")
        sys.stdout.flush()
    trials = len(pooled["riann"])
    mean_rmse = {n: np.mean([rmse_deg(x) for x in pooled[n]]) for n in names}
    worst = {n: np.max([rmse_deg(x) for x in pooled[n]]) for n in names}
    print(f"| mean / worst of {trials} | " + " | ".join(f"{mean_rmse[n]:.2f} / {worst[n]:.2f}" for n in names)
          + " | | | |")
    e = {k: np.concatenate(v) for k, v in pooled.items()}
    print("\npooled correlation of RIANN's and VQF's inclination errors:")
    for k, v in correlations(e).items():
        print(f"  {k:22s} {v:+.3f}")
    print("\nreported σ against the errors (pooled): coverage 95 % | NEES/DOF | rank corr σ~e | top/bottom decile e")
    for s in specs:
        cov, nees, rank, ratio = sigma_stats(e[s], e[s + "/s"])
        print(f"  {s:24s} {cov:6.1f} % | {nees:6.2f} | {rank:+.2f} | {ratio:5.2f}")
    rho = correlations(e)["vector"]
    sr, sv = e["riann/s"], e["vqf/s"]
    expect = 2 * (sr**2 + sv**2 - 2 * rho * sr * sv)
    d2 = e["d"] ** 2
    print(f"\ndisagreement d: RMS {np.degrees(np.sqrt(np.mean(d2))):.2f}°, σ-model RMS "
          f"{np.degrees(np.sqrt(np.mean(expect))):.2f}°, share of samples with d > {AGREE_DEG:g}°: "
          f"{100 * np.mean(np.degrees(e['d']) > AGREE_DEG):.1f} %, d²/E[d²] > χ²₂(0.95): "
          f"{100 * np.mean(2 * d2 / expect > CHI2_2_95):.1f} %")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
