"""Fit RIANN's inclination uncertainty model (stage 8) on the shared BROAD trials, and show what chose its inputs.

Runs RIANN (default parameters, 9D: the inclination is the same as without a field) over each trial, keeps stage 8's
inputs per scored sample and the inclination error ``e``, prints how the error grows with each input (the mean error per
quintile of the input), then fits the constants of ``σ_i² = σ₀² + (k_s·s)² + (k_b·σ_b)² + (k_r·ω)²`` (+ the hand-over's
σ after a hole, no constant) by maximum likelihood of the 2-D Gaussian (``e²/σ_i²`` is χ² with 2 degrees of freedom)
over all scored samples, each trial weighted equally, and prints coverage and NEES per trial with the fitted and with
the current constants (riann_ros/estimators/riann/s8_uncertainty.py). Then the heading: the field's σ fitted by maximum
likelihood on the samples whose heading the field corrects, and the heading's coverage while the field corrects it and
while the gyro holds it after one. Last the heading's share of a hole's gyro bridge (``K_BRIDGE``: the bridge's σ is a
bound made for the inclination's hand-over), fitted by maximum likelihood on the trials run again with holes
(``dropout:0.1-0.6s@10s``, one fixed draw), the field's σ as fitted.

    RIANN_BROAD_DIR=... python bench/fit_uncertainty.py [--step 5] [--cache DIR]

``--cache`` keeps the per-trial features between runs (derived from BROAD: keep it outside the repository).
"""

from __future__ import annotations

import argparse
import os
import sys
from pathlib import Path

import numpy as np
from scipy.optimize import minimize

from riann_ros import quaternion as quat
from riann_ros.datasets.broad import broad_files, find_broad_dir, read_broad
from riann_ros.estimators.riann.estimator import RiannEstimator
from riann_ros.estimators.riann.s8_uncertainty import (
    FEATURES,
    FREE,
    HELD,
    K_BIAS,
    K_BRIDGE,
    K_RATE,
    K_SPREAD,
    MAG_SD,
    SIGMA0,
    USED,
    heading_sigma,
    inclination_sigma,
)
from riann_ros.evaluation.perturb import parse_condition
from riann_ros.magcal.input import MagConfig
from riann_ros.stream import EstimatorStream, GateConfig

CHI2_2_95 = 5.991  # χ²₂(0.95)
CHI2_1_95 = 3.841  # χ²₁(0.95)
HOLES = "dropout:0.1-0.6s@10s"


def trial_features(path: Path, est: RiannEstimator, holes: bool = False) -> dict[str, np.ndarray]:
    """Of the scored samples of one trial, run in 9D (the inclination is the same as in 6D), as recorded or with
    holes: stage 8's inclination features ``f`` and heading features ``yf``, the inclination error ``e`` and the
    heading error ``eh`` (rad)."""
    rec = read_broad(path)
    if holes:  # through the evaluator's gate, as it scores them: a hole past max_dt is a gap
        rec = parse_condition(HOLES).start([np.random.default_rng(0)])[0](rec)
        est.reset()
        f: list[np.ndarray] = []
        yf: list[np.ndarray] = []
        run = est.update_batch

        def kept(*args: object) -> np.ndarray:  # stage 8's features of each run between restarts
            out = run(*args)  # type: ignore[arg-type]
            f.append(est.last.features.copy())
            yf.append(est.last.yaw_features.copy())
            return out

        est.update_batch = kept  # type: ignore[method-assign]
        q, acc = EstimatorStream(est, GateConfig(), MagConfig(use_mag="auto")).process_batch(
            rec.stamps_ns, rec.acc, rec.gyr, rec.mag)
        del est.update_batch
        ff, yy = np.full((len(q), len(FEATURES)), np.nan), np.full((len(q), yf[0].shape[1]), np.nan)
        ff[acc], yy[acc] = np.vstack(f), np.vstack(yf)
        assert rec.quat_ref is not None
        e = quat.inclination_error(rec.quat_ref, q)
        ok = np.asarray(rec.score_mask, dtype=bool) & acc & np.isfinite(e)
        return {"f": ff[ok], "yf": yy[ok], "e": e[ok], "eh": quat.heading_error(rec.quat_ref, q)[ok]}
    dt = np.diff(rec.stamps_ns, prepend=rec.stamps_ns[0]) * 1e-9
    dt[0] = float(np.median(dt[1:]))
    est.reset()
    q = est.update_batch(rec.acc, rec.gyr, dt, rec.mag)
    assert rec.quat_ref is not None
    e = quat.inclination_error(rec.quat_ref, q)
    ok = np.asarray(rec.score_mask, dtype=bool) & np.isfinite(e)
    return {"f": est.last.features[ok], "yf": est.last.yaw_features[ok], "e": e[ok],
            "eh": quat.heading_error(rec.quat_ref, q)[ok]}


def load(step: int, cache: Path | None, holes: bool = False) -> dict[str, dict[str, np.ndarray]]:
    d = find_broad_dir()
    if d is None:
        sys.exit("no BROAD trials: set RIANN_BROAD_DIR")
    est = RiannEstimator()
    out = {}
    for p in broad_files(d):
        c = cache / f"{p.stem}{'_holes' if holes else ''}.npz" if cache else None
        z = dict(np.load(c)) if c is not None and c.exists() else {}
        if not z or z["f"].shape[1] != len(FEATURES):  # not cached, or cached with other inputs
            z = trial_features(p, est, holes)
            if c is not None:
                np.savez(c, **z)
        out[p.stem[:2]] = {k: v[::step] for k, v in z.items()}
        e = z["e"]
        print(f"{p.stem}: {len(e)} scored samples, RMSE {np.degrees(np.sqrt(np.mean(e**2))):.2f}°", file=sys.stderr)
    return out


def quintiles(data: dict[str, dict[str, np.ndarray]]) -> None:
    f = np.vstack([v["f"] for v in data.values()])
    e = np.degrees(np.concatenate([v["e"] for v in data.values()]))
    print("mean error (deg) per quintile of each input (all trials):")
    for j, name in enumerate(FEATURES):
        x = f[:, j]
        edges = np.quantile(x, [0.2, 0.4, 0.6, 0.8])
        b = np.searchsorted(edges, x)
        means = [float(e[b == i].mean()) if (b == i).any() else float("nan") for i in range(5)]
        rho = np.corrcoef(np.argsort(np.argsort(x)), np.argsort(np.argsort(e)))[0, 1]
        print(f"  {name:11s} " + " ".join(f"{m:5.2f}" for m in means) + f"   rank corr {rho:+.2f}")


def nll(logk: np.ndarray, data: dict[str, dict[str, np.ndarray]]) -> float:
    k = tuple(np.exp(logk))
    total = 0.0
    for v in data.values():
        f, e = v["f"], v["e"]
        s2 = inclination_sigma(f, k) ** 2
        total += float(np.mean(np.log(s2) + e * e / (2.0 * s2)))
    return total


def report(k: tuple[float, ...], data: dict[str, dict[str, np.ndarray]], label: str) -> None:
    print(f"{label}: σ₀ {np.degrees(k[0]):.3f}°, k_s {k[1]:.3f}, k_b {k[2]:.3f} s, k_r {k[3]:.5f} s")
    cov_all, nees_all, n_all = 0.0, 0.0, 0
    es: list[np.ndarray] = []
    ss: list[np.ndarray] = []
    print("  trial  coverage95  NEES/DOF  top/bottom decile error")
    for name, v in data.items():
        f, e = v["f"], v["e"]
        s = inclination_sigma(f, k)  # type: ignore[arg-type]
        r = e * e / (s * s)
        dec = np.quantile(s, [0.1, 0.9])
        ratio = e[s >= dec[1]].mean() / e[s <= dec[0]].mean()
        print(f"  {name}     {100 * np.mean(r <= CHI2_2_95):6.1f} %   {np.mean(r) / 2:6.2f}    {ratio:5.2f}")
        es.append(e)
        ss.append(s)
        cov_all += float(np.sum(r <= CHI2_2_95))
        nees_all += float(np.sum(r) / 2)
        n_all += len(e)
    e, s = np.concatenate(es), np.concatenate(ss)
    dec = np.quantile(s, [0.1, 0.9])
    ratio = e[s >= dec[1]].mean() / e[s <= dec[0]].mean()
    print(f"  all    {100 * cov_all / n_all:6.1f} %   {nees_all / n_all:6.2f}    {ratio:5.2f}")


def heading_nll(log_sd: np.ndarray, data: dict[str, dict[str, np.ndarray]]) -> float:
    """Minus the log-likelihood (1 DOF, per trial weighted equally) of the heading errors while a field corrects."""
    total = 0.0
    for v in data.values():
        used = v["yf"][:, 0] == USED
        if used.any():
            s = heading_sigma(v["yf"][used], inclination_sigma(v["f"][used]), float(np.exp(log_sd[0])))
            total += float(np.mean(2.0 * np.log(s) + (v["eh"][used] / s) ** 2))
    return total


def bridge_nll(log_k: np.ndarray, data: dict[str, dict[str, np.ndarray]], mag_sd: float) -> float:
    """Minus the log-likelihood (1 DOF, per trial weighted equally) of the heading errors that carry a bridge's share,
    with the bridges' σ scaled by ``exp(log_k)``."""
    total = 0.0
    for v in data.values():
        sel = (v["yf"][:, 0] != FREE) & (v["yf"][:, 1] > 0.0)
        if sel.any():
            s = heading_sigma(v["yf"][sel], inclination_sigma(v["f"][sel]), mag_sd, float(np.exp(log_k[0])))
            total += float(np.mean(2.0 * np.log(s) + (v["eh"][sel] / s) ** 2))
    return total


def heading_report(mag_sd: float, data: dict[str, dict[str, np.ndarray]], label: str,
                   k_bridge: float = K_BRIDGE) -> None:
    print(f"{label}: heading σ of the field {np.degrees(mag_sd):.2f}°, bridge share {k_bridge:.3f}")
    print("  trial  samples used/held  coverage95 used  held   NEES")
    tot: dict[str, list[float]] = {"used": [0, 0], "held": [0, 0]}
    for name, v in data.items():
        s = heading_sigma(v["yf"], inclination_sigma(v["f"]), mag_sd, k_bridge)
        r = (v["eh"] / s) ** 2
        cells = []
        for key, state in (("used", USED), ("held", HELD)):
            sel = v["yf"][:, 0] == state
            tot[key][0] += int(sel.sum())
            tot[key][1] += int(np.sum(r[sel] <= CHI2_1_95))
            cells.append(f"{100 * np.mean(r[sel] <= CHI2_1_95):6.1f} %" if sel.any() else "     –  ")
        known = v["yf"][:, 0] != FREE
        nees = f"{np.mean(r[known]):.2f}" if known.any() else "–"
        n_used, n_held = int(np.sum(v["yf"][:, 0] == USED)), int(np.sum(v["yf"][:, 0] == HELD))
        print(f"  {name}     {n_used:6d}/{n_held:<6d}     {cells[0]}   {cells[1]}  {nees}")
    print("  all                       " + "   ".join(
        f"{100 * t[1] / t[0]:6.1f} %" if t[0] else "     –  " for t in tot.values()))


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--step", type=int, default=5, help="use every n-th scored sample in the fit")
    ap.add_argument("--cache", type=Path, default=None, help="directory for the per-trial features")
    a = ap.parse_args()
    if a.cache:
        os.makedirs(a.cache, exist_ok=True)
    data = load(a.step, a.cache)
    quintiles(data)
    x0 = np.log([max(SIGMA0, 0.1 * np.pi / 180), K_SPREAD, K_BIAS, K_RATE])
    r = minimize(nll, x0, args=(data,), method="Powell")
    report((SIGMA0, K_SPREAD, K_BIAS, K_RATE), data, "current constants")
    report(tuple(np.exp(r.x)), data, "fitted (maximum likelihood)")
    h = minimize(heading_nll, np.log([MAG_SD]), args=(data,), method="Powell")
    heading_report(MAG_SD, data, "heading, current constant")
    mag_sd = float(np.exp(h.x[0]))
    heading_report(mag_sd, data, "heading, fitted (maximum likelihood while the field corrects)")
    holes = load(a.step, a.cache, holes=True)
    b = minimize(bridge_nll, np.log([K_BRIDGE]), args=(holes, mag_sd), method="Powell")
    heading_report(MAG_SD, holes, f"with holes ({HOLES}), current constants")
    heading_report(mag_sd, holes, f"with holes ({HOLES}), fitted (maximum likelihood where a bridge counts)",
                   float(np.exp(b.x[0])))


if __name__ == "__main__":
    main()
