"""Does the IMU stream itself show how a regular low-rate stream was made?

Usage::

    .venv/bin/python bench/study_sample_model.py [--rates 25,50,100]

For every BROAD trial (``$RIANN_BROAD_DIR``) and rate, the recording is made a regular stream three ways with the
evaluator's perturbations (``rate:HZ`` interval means stamped at the end, ``rate:HZ:points`` the signal at the
stamp, ``rate:HZ:lowpass`` a first-order low-pass of time constant half a step sampled at the stamp), and a few
reference-free observables of the gyro and the accelerometer are printed per trial: the share of the power
(above 2 % of the rate) within the top 40 % of the band below Nyquist, the lag-1 autocorrelation of the first
differences, and the same over the moving samples only. The last lines say, per observable, whether one threshold
puts every points stream on one side and every means / low-pass stream on the other (per rate and over all rates).
"""

from __future__ import annotations

import argparse
import sys

import numpy as np
from numpy.typing import NDArray

from riann_ros.datasets.broad import broad_files, find_broad_dir, read_broad
from riann_ros.evaluation.perturb import parse_perturbation

KINDS = ("points", "means", "lowpass")


def hf_share(x: NDArray[np.float64], fs: float) -> float:
    """Power in 0.3–0.5 fs over power in 0.02–0.5 fs (periodogram, mean removed per channel, channels summed)."""
    x = x - x.mean(axis=0)
    p = (np.abs(np.fft.rfft(x * np.hanning(len(x))[:, None], axis=0)) ** 2).sum(axis=1)
    f = np.fft.rfftfreq(len(x), 1.0 / fs)
    return float(p[f >= 0.3 * fs].sum() / p[f >= 0.02 * fs].sum())


def diff_ac1(x: NDArray[np.float64]) -> float:
    """Lag-1 autocorrelation of the first differences (channels pooled)."""
    d = np.diff(x, axis=0)
    d = d - d.mean(axis=0)
    return float((d[1:] * d[:-1]).sum() / (d * d).sum())


def observables(rec, fs: float) -> dict[str, float]:
    moving = rec.score_mask
    out = {}
    for name, x in (("gyr", rec.gyr), ("acc", rec.acc)):
        out[f"{name} hf"] = hf_share(x, fs)
        out[f"{name} dac1"] = diff_ac1(x)
        out[f"{name} dac1 moving"] = diff_ac1(x[moving]) if moving.sum() > 100 else float("nan")
    return out


def make(rec, text: str):
    tr = parse_perturbation(text).start(np.random.default_rng(0))
    return tr(rec)


def separable(vals: dict[str, list[float]]) -> str:
    """Whether one threshold separates points from the other two (the margin, relative to the spread)."""
    p = np.asarray(vals["points"])
    o = np.asarray(vals["means"] + vals["lowpass"])
    p, o = p[np.isfinite(p)], o[np.isfinite(o)]
    if p.min() > o.max():
        return f"yes (points > {o.max():.3g}, min {p.min():.3g})"
    if p.max() < o.min():
        return f"yes (points < {o.min():.3g}, max {p.max():.3g})"
    overlap = np.mean([(p > v).mean() for v in o])
    return f"no (P(points > other) = {overlap:.2f})"


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--rates", default="25,50,100")
    args = ap.parse_args()
    d = find_broad_dir()
    if d is None:
        print("BROAD not found (set RIANN_BROAD_DIR)", file=sys.stderr)
        return 1
    rates = [float(r) for r in args.rates.split(",")]
    table: dict[tuple[float, str], dict[str, list[float]]] = {}
    for path in broad_files(d):
        rec = read_broad(path)
        for hz in rates:
            for kind, suffix in zip(KINDS, (":points", "", ":lowpass"), strict=True):
                obs = observables(make(rec, f"rate:{hz:g}{suffix}"), hz)
                cells = " ".join(f"{k} {v:.3f}" for k, v in obs.items())
                print(f"{path.stem[:2]} {hz:g} Hz {kind:8s} {cells}")
                for k, v in obs.items():
                    table.setdefault((hz, k), {kk: [] for kk in KINDS})[kind].append(v)
    print()
    names = list(dict.fromkeys(k for _, k in table))
    for name in names:
        for hz in rates:
            print(f"{name:16s} {hz:5g} Hz: separable {separable(table[(hz, name)])}")
        pooled = {kind: [v for hz in rates for v in table[(hz, name)][kind]] for kind in KINDS}
        print(f"{name:16s}   all: separable {separable(pooled)}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
