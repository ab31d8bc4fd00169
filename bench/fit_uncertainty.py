"""Fit RIANN's inclination uncertainty model (stage 8) on the shared BROAD trials, and show what chose its inputs.

Runs RIANN (default parameters, 6D: the inclination is the same with a field) over each trial, keeps stage 8's
inputs per scored sample and the inclination error ``e``, prints how the error grows with each input (the mean
error per quintile of the input), then fits the constants of ``σ_i² = σ₀² + (k_s·s)² + (k_b·σ_b)²``
(+ the hand-over's σ after a hole, no constant) by maximum likelihood of the 2-D Gaussian (``e²/σ_i²`` is χ² with
2 degrees of freedom) over all scored samples, each trial weighted equally, and prints coverage and NEES per
trial with the fitted and with the current constants (riann_ros/estimators/riann/s8_uncertainty.py).

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
from riann_ros.estimators.riann.s8_uncertainty import FEATURES, K_BIAS, K_SPREAD, SIGMA0, inclination_sigma

CHI2_2_95 = 5.991  # χ²₂(0.95)


def trial_features(path: Path, est: RiannEstimator) -> tuple[np.ndarray, np.ndarray]:
    """(features (n, k), inclination error (n,) rad) of the scored samples of one trial."""
    rec = read_broad(path)
    dt = np.diff(rec.stamps_ns, prepend=rec.stamps_ns[0]) * 1e-9
    dt[0] = float(np.median(dt[1:]))
    est.reset()
    q = est.update_batch(rec.acc, rec.gyr, dt)
    f = est.uncertainty.features
    assert rec.quat_ref is not None
    e = quat.inclination_error(rec.quat_ref, q)
    ok = np.asarray(rec.score_mask, dtype=bool) & np.isfinite(e)
    return f[ok], e[ok]


def load(step: int, cache: Path | None) -> dict[str, tuple[np.ndarray, np.ndarray]]:
    d = find_broad_dir()
    if d is None:
        sys.exit("no BROAD trials: set RIANN_BROAD_DIR")
    est = RiannEstimator()
    out = {}
    for p in broad_files(d):
        c = cache / f"{p.stem}.npz" if cache else None
        if c is not None and c.exists():
            z = np.load(c)
            f, e = z["f"], z["e"]
        else:
            f, e = trial_features(p, est)
            if c is not None:
                np.savez(c, f=f, e=e)
        out[p.stem[:2]] = (f[::step], e[::step])
        print(f"{p.stem}: {len(e)} scored samples, RMSE {np.degrees(np.sqrt(np.mean(e**2))):.2f}°", file=sys.stderr)
    return out


def quintiles(data: dict[str, tuple[np.ndarray, np.ndarray]]) -> None:
    f = np.vstack([v[0] for v in data.values()])
    e = np.degrees(np.concatenate([v[1] for v in data.values()]))
    print("mean error (deg) per quintile of each input (all trials):")
    for j, name in enumerate(FEATURES):
        x = f[:, j]
        edges = np.quantile(x, [0.2, 0.4, 0.6, 0.8])
        b = np.searchsorted(edges, x)
        means = [float(e[b == i].mean()) if (b == i).any() else float("nan") for i in range(5)]
        rho = np.corrcoef(np.argsort(np.argsort(x)), np.argsort(np.argsort(e)))[0, 1]
        print(f"  {name:11s} " + " ".join(f"{m:5.2f}" for m in means) + f"   rank corr {rho:+.2f}")


def nll(logk: np.ndarray, data: dict[str, tuple[np.ndarray, np.ndarray]]) -> float:
    k = tuple(np.exp(logk))
    total = 0.0
    for f, e in data.values():
        s2 = inclination_sigma(f, k) ** 2
        total += float(np.mean(np.log(s2) + e * e / (2.0 * s2)))
    return total


def report(k: tuple[float, ...], data: dict[str, tuple[np.ndarray, np.ndarray]], label: str) -> None:
    print(f"{label}: σ₀ {np.degrees(k[0]):.3f}°, k_s {k[1]:.3f}, k_b {k[2]:.3f} s")
    cov_all, nees_all, n_all = 0.0, 0.0, 0
    es: list[np.ndarray] = []
    ss: list[np.ndarray] = []
    print("  trial  coverage95  NEES/DOF  top/bottom decile error")
    for name, (f, e) in data.items():
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


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--step", type=int, default=5, help="use every n-th scored sample in the fit")
    ap.add_argument("--cache", type=Path, default=None, help="directory for the per-trial features")
    a = ap.parse_args()
    if a.cache:
        os.makedirs(a.cache, exist_ok=True)
    data = load(a.step, a.cache)
    quintiles(data)
    x0 = np.log([SIGMA0, K_SPREAD, K_BIAS])
    r = minimize(nll, x0, args=(data,), method="Powell")
    report((SIGMA0, K_SPREAD, K_BIAS), data, "current constants")
    report(tuple(np.exp(r.x)), data, "fitted (maximum likelihood)")


if __name__ == "__main__":
    main()
