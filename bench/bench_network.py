#!/usr/bin/env python3
"""The RIANN copies in one call: candidates timed against the published model, interleaved in one run.

    .venv/bin/python bench/bench_network.py [--reps 7] [--calls 300] [--rows 10000] [--trial 07] [--no-numpy]

Candidates (each maps rows (copies, T, 7) and states (copies, 2, 1, 1, 200) to outputs and next states, the
same meaning as the published session run once per copy):

* ``published 1 copy``: the published session, one run (the reference of the ratios);
* ``published × 4``: the published session once per copy (the reference);
* ``I/O binding × 4``: the same four runs with preallocated inputs and outputs bound once (OrtValue);
* ``batched run()``: the published graph with a batch axis
  (:func:`riann_ros.estimators.riann.s4c_batch_axis.batch_model`), one ``InferenceSession.run`` for all copies;
* ``BatchedModel.run``: :class:`riann_ros.estimators.riann.s4b_model.BatchedModel` (the batched graph, I/O binding);
* ``numpy GRU × 4``: the two GRU layers stepped in numpy (float32) from the file's initializers (timed at
  T = ``--rows`` on a thirtieth of the calls; in the trial check on the first trial only).

Timing: per call at T = 1 and 2 rows (the node's path), and per row over T = ``--rows`` (offline). Each repetition
runs every candidate once, in turn; min and median over repetitions, the ratio to the published single copy per
repetition (median). ONNX Runtime single-threaded. Exactness: max |difference| to the per-copy published run over
outputs and states, on synthetic rows (T = 1 from a random state, and T = 2000), and with ``--trial`` on BROAD
trials (their rows at the native step, four rotated copies as the ensemble feeds them: the whole trial in one
call, and its first ``--steps`` rows one call per row, each against the published model called alike).

Then the rows of the copies from one row: ``rotate_rows`` per copy against one matmul with a block-diagonal
(copies, 7, 7) stack (``copy_rows``, what the network stage uses), timed, and compared on the BROAD trials.
The estimator's per-sample cost against another version: ``bench/bench_update.py``.
"""

from __future__ import annotations

import argparse
import os
import statistics
import sys
import time
from collections.abc import Callable
from pathlib import Path

os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")  # numpy's BLAS single-threaded like ONNX Runtime

import numpy as np
import onnxruntime as ort

from riann_ros.estimators.riann import s4b_model as nw
from riann_ros.estimators.riann import s4c_batch_axis as pb
from riann_ros.estimators.riann.s4a_ensemble import copy_rows, frames, rotate_rows

Fn = Callable[[np.ndarray, np.ndarray], tuple[np.ndarray, np.ndarray]]


# -- the numpy GRU (candidate c), weights read from the ONNX file with the module's wire-format reader -----
def _tensor(t: bytes) -> tuple[str, np.ndarray | None]:
    """name, array of a float32 TensorProto (raw_data or float_data); None for other types."""
    name, dims, data, float32 = "", [], None, True
    for n, w, p in pb.fields(t):
        if n == 1:  # dims: one varint each, or packed
            dims += [pb.varint(p, 0)[0]] if w == 0 else _packed(p)
        elif n == 2:
            float32 = pb.varint(p, 0)[0] == 1
        elif n == 8:
            name = p.decode()
        elif n in (4, 9):  # float_data (packed), raw_data: little-endian float32
            data = np.frombuffer(p, "<f4")
    return name, data.reshape(dims) if float32 and data is not None else None


def _packed(p: bytes) -> list[int]:
    out, i = [], 0
    while i < len(p):
        v, i = pb.varint(p, i)
        out.append(v)
    return out


def read_graph(path: str) -> tuple[dict[str, np.ndarray], list[dict[str, int]]]:
    """Initializers and Constant values by name; the GRU nodes' integer attributes, in order."""
    model = pb.fields(open(path, "rb").read())
    graph = pb.fields(next(p for n, _, p in model if n == pb.MODEL_GRAPH))
    values: dict[str, np.ndarray] = {}
    grus = []
    for n, _, p in graph:
        if n == 5:  # initializer
            k, t = _tensor(p)
            if t is not None:
                values[k] = t
        elif n == 1:  # node: output 2, op_type 4, attribute 5 (name 1, i 3, t 5, s 4, strings 9)
            f = pb.fields(p)
            op = next(q.decode() for m, _, q in f if m == 4)
            attrs = [pb.fields(q) for m, _, q in f if m == 5]
            t = _tensor(next(q for m, _, q in attrs[0] if m == 5))[1] if op == "Constant" else None
            if t is not None:
                values[next(q.decode() for m, _, q in f if m == 2)] = t
            elif op == "GRU":
                grus.append({next(q.decode() for m, _, q in a if m == 1): next(
                    (pb.varint(q, 0)[0] for m, _, q in a if m == 3), -1) for a in attrs})
    return values, grus


class NumpyGRU:
    """The published graph in numpy float32: (x - mean) / std, GRU 7→200, GRU 200→200 (ONNX gate order z, r, h;
    linear_before_reset = 1: h̃ = tanh(Wh x + bWh + r ⊙ (Rh h + bRh))), linear 200→4, normalise."""

    def __init__(self, path: str, order: str = "zrh") -> None:
        v, grus = read_graph(path)
        assert [g.get("linear_before_reset") for g in grus] == [1, 1], grus
        assert [g.get("hidden_size") for g in grus] == [200, 200], grus
        self.mean, self.std = v["12"].reshape(7), v["14"].reshape(7)
        perm = {"zrh": [0, 1, 2], "rzh": [1, 0, 2]}[order]  # rzh: the wrong order, to show the check bites

        def gates(a: np.ndarray) -> np.ndarray:
            return np.concatenate([a[200 * k : 200 * (k + 1)] for k in perm])

        self.layers = [(np.ascontiguousarray(gates(v[w][0]).T), np.ascontiguousarray(gates(v[r][0]).T),
                        gates(v[b][0][:600]), gates(v[b][0][600:])) for w, r, b in (("169", "170", "171"),
                                                                                    ("189", "190", "191"))]
        self.lin = np.ascontiguousarray(v["final.lin.weight"][:, :, 0].T)
        self.bias = v["final.lin.bias"]

    @staticmethod
    def _cell(gx: np.ndarray, h: np.ndarray, r: np.ndarray, br: np.ndarray) -> np.ndarray:
        gh = h @ r + br
        zr = 1.0 / (1.0 + np.exp(-(gx[:, :400] + gh[:, :400])))
        n = np.tanh(gx[:, 400:] + zr[:, 200:] * gh[:, 400:])
        return n + zr[:, :200] * (h - n)

    def __call__(self, x: np.ndarray, h: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        (w1, r1, b1, c1), (w2, r2, b2, c2) = self.layers
        h1, h2 = h[:, 0, 0, 0].copy(), h[:, 1, 0, 0].copy()
        gx1 = ((x - self.mean) / self.std) @ w1 + b1
        ys = np.empty((x.shape[0], x.shape[1], 200), np.float32)
        for t in range(x.shape[1]):
            h1 = self._cell(gx1[:, t], h1, r1, c1)
            h2 = self._cell(h1 @ w2 + b2, h2, r2, c2)
            ys[:, t] = h2
        o = ys @ self.lin + self.bias
        o /= np.sqrt((o * o).sum(-1, keepdims=True))
        return o, np.stack([h1, h2], 1)[:, :, None, None, :]


# -- candidates ---------------------------------------------------------------------------------------
class BoundPerCopy:
    """The published session once per copy, inputs and outputs bound once to preallocated buffers (T fixed)."""

    def __init__(self, session: ort.InferenceSession, copies: int, rows: int) -> None:
        self.session = session
        self.x = np.zeros((copies, 1, rows, 7), np.float32)
        self.h = np.zeros((copies, 2, 1, 1, 200), np.float32)
        self.out = np.zeros((copies, 1, rows, 4), np.float32)
        self.hn = np.zeros_like(self.h)
        self.bindings = []
        for m in range(copies):
            b = session.io_binding()
            b.bind_cpu_input("input", self.x[m])
            b.bind_cpu_input("h0", self.h[m])
            b.bind_output("output", "cpu", 0, np.float32, list(self.out[m].shape), self.out[m].ctypes.data)
            b.bind_output("hn", "cpu", 0, np.float32, list(self.hn[m].shape), self.hn[m].ctypes.data)
            self.bindings.append(b)

    def __call__(self, x: np.ndarray, h: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        self.x[:, 0] = x
        self.h[...] = h
        for b in self.bindings:
            self.session.run_with_iobinding(b)
        return self.out[:, 0].copy(), self.hn.copy()


def batched_run(session: ort.InferenceSession) -> Fn:
    def run(x: np.ndarray, h: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        c = len(x)
        h0 = np.ascontiguousarray(h.reshape(c, 2, 1, 200).transpose(1, 2, 0, 3))
        out, hn = session.run(["output", "hn"], {"input": x, "h0": h0})
        return out, np.ascontiguousarray(hn.transpose(2, 0, 1, 3)).reshape(c, 2, 1, 1, 200)

    return run


def candidates(net: nw.BatchedModel, rows: int, numpy: bool) -> dict[str, Fn]:
    s = net.session
    batched = nw._session(pb.batch_model(net.path.read_bytes()), 1)
    out: dict[str, Fn] = {
        "published 1 copy": lambda x, h: s.run(["output", "hn"], {"input": x[:1], "h0": h[0]}),
        "published × 4": net.run_per_copy,
        "batched run()": batched_run(batched),
        "BatchedModel.run": net.run,
    }
    if rows <= 2:
        out["I/O binding × 4"] = BoundPerCopy(s, net.copies, rows)
    if numpy:
        out["numpy GRU × 4"] = NumpyGRU(str(net.path))
    return out


def time_calls(fns: dict[str, Fn], x: np.ndarray, h: np.ndarray, calls: int, reps: int) -> dict[str, list[float]]:
    """µs per call of each candidate, one list entry per repetition (candidates interleaved)."""
    res: dict[str, list[float]] = {k: [] for k in fns}
    for _ in range(reps):
        for k, f in fns.items():
            n = max(1, calls // 30) if k.startswith("numpy") and x.shape[1] > 2 else calls
            t0 = time.perf_counter()
            for _ in range(n):
                f(x, h)
            res[k].append((time.perf_counter() - t0) / n * 1e6)
    return res


def print_table(title: str, res: dict[str, list[float]], ref: str, per: float, unit: str) -> None:
    print(f"\n{title}")
    print(f"| candidate | min {unit} | median {unit} | ratio to {ref} (median of per-rep) |")
    print("|---|---:|---:|---:|")
    for k, v in res.items():
        ratio = statistics.median(a / b for a, b in zip(v, res[ref], strict=True))
        print(f"| {k} | {min(v) / per:.1f} | {statistics.median(v) / per:.1f} | {ratio:.2f} |")


def max_diff(a: tuple[np.ndarray, np.ndarray], b: tuple[np.ndarray, np.ndarray]) -> float:
    return max(float(np.abs(p.astype(np.float64) - q).max()) for p, q in zip(a, b, strict=True))


def exactness(net: nw.BatchedModel, fns: dict[str, Fn], rows: int) -> None:
    print("\nexactness: max |candidate - published per copy| over outputs and states")
    rng = np.random.default_rng(5)
    h = rng.uniform(-0.9, 0.9, (net.copies, 2, 1, 1, 200)).astype(np.float32)
    for k, f in fns.items():
        if "1 copy" in k or "binding" in k:
            continue
        x1, xl = nw.probe(net.copies, 1, seed=7), nw.probe(net.copies, rows, seed=8)
        step, seq = max_diff(f(x1, h), net.run_per_copy(x1, h)), max_diff(f(xl, h), net.run_per_copy(xl, h))
        print(f"  {k}: T=1 from a random state {step:.3g}; T={rows} {seq:.3g}")
    gru = next((f for k, f in fns.items() if k.startswith("numpy")), None)
    if isinstance(gru, NumpyGRU):
        wrong = NumpyGRU(str(net.path), order="rzh")
        x = nw.probe(net.copies, 200, seed=9)
        print(f"  numpy GRU with the gate order r, z, h instead of z, r, h: {max_diff(wrong(x, h), gru(x, h)):.3g}")


def trial_rows(path: Path, copies: int, dtype: type = np.float32) -> np.ndarray:
    """A BROAD trial's rows at its native step, in each copy's rotated frame as the ensemble feeds them."""
    from riann_ros.datasets.broad import read_broad

    rec = read_broad(path)
    dt = float(np.median(np.diff(rec.stamps_ns))) * 1e-9
    x = np.column_stack([rec.acc, rec.gyr, np.full(len(rec.acc), dt)])
    return np.stack([x if m == 0 else rotate_rows(x, r) for m, r in enumerate(frames(copies))]).astype(dtype)


def trial_files(spec: str) -> list[Path]:
    from riann_ros.datasets.broad import broad_files, find_broad_dir

    d = find_broad_dir()
    if d is None:
        print("\nBROAD trials not found (RIANN_BROAD_DIR): trial exactness skipped")
        return []
    files = broad_files(d)
    return files if spec == "all" else [p for p in files if p.name.split("_")[0] in spec.split(",")]


def row_by_row(f: Fn, x: np.ndarray, h: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    out = np.empty((len(x), x.shape[1], 4), np.float32)
    for t in range(x.shape[1]):
        o, h = f(x[:, t : t + 1], h)
        out[:, t] = o[:, 0]
    return out, h


def trial_exactness(net: nw.BatchedModel, fns: dict[str, Fn], spec: str, steps: int) -> None:
    """Per trial: the whole trial in one call, and its first ``steps`` rows one call each, against the published
    model run copy by copy in the same calls; and the published model's own spread between the two."""
    files = trial_files(spec)
    if files:
        print(f"\nBROAD trials, max |candidate - published per copy| (outputs and states); first {steps} rows one "
              "call each; last column: the published model's own row-by-row outputs against its one-call outputs")
        print("| trial | rows | candidate | whole trial, one call | row by row | published: row by row vs one call |")
        print("|---|---:|---|---:|---:|---:|")
    for i, path in enumerate(files):
        x = trial_rows(path, net.copies)
        h0 = net.fresh_state()
        want = net.run_per_copy(x, h0)
        want_rows = row_by_row(net.run_per_copy, x[:, :steps], h0)
        spread = max_diff((want_rows[0],), (want[0][:, :steps],))
        for k, f in fns.items():
            if "1 copy" in k or "binding" in k or ("×" in k and not (k.startswith("numpy") and i == 0)):
                continue
            whole = max_diff(f(x, h0), want)
            rows = max_diff(row_by_row(f, x[:, :steps], h0), want_rows)
            print(f"| {path.name[:2]} | {x.shape[1]} | {k} | {whole:.3g} | {rows:.3g} | {spread:.3g} |")


# -- the estimator ----------------------------------------------------------------------------------------
def rotation_check(spec: str, reps: int) -> None:
    rots = frames(4)
    one = copy_rows(rots)

    def loop(x: np.ndarray) -> np.ndarray:
        xs = np.empty((len(rots), len(x), 7), np.float32)
        for m, r in enumerate(rots):
            xs[m] = x if m == 0 else rotate_rows(x, r)
        return xs

    x1 = nw.probe(1, 1, seed=3)[0].astype(np.float64)
    res: dict[str, list[float]] = {"rotate_rows per copy": [], "one matmul": []}
    for _ in range(reps):
        for k, f in (("rotate_rows per copy", loop), ("one matmul", one)):
            t0 = time.perf_counter()
            for _ in range(2000):
                f(x1)
            res[k].append((time.perf_counter() - t0) / 2000 * 1e6)
    print_table("rows of the 4 copies from one row (the node's path)", res, "rotate_rows per copy", 1.0, "µs")
    diff = n = 0
    for path in trial_files(spec):
        x = trial_rows(path, 1, np.float64)[0]
        diff += int((loop(x) != one(x)).sum())
        n += 4 * x.size
    if n:
        print(f"  BROAD trials: {diff} of {n} float32 values differ between the two")


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--reps", type=int, default=7)
    ap.add_argument("--calls", type=int, default=300, help="calls per repetition at T = 1 and 2")
    ap.add_argument("--rows", type=int, default=10000, help="T of the throughput test")
    ap.add_argument("--trial", default="all", help="BROAD trials for the exactness check: 'all', numbers "
                    "like 02,07, or '' for none")
    ap.add_argument("--steps", type=int, default=3000, help="rows of each trial also fed one call per row")
    ap.add_argument("--no-numpy", action="store_true", help="leave out the numpy GRU")
    a = ap.parse_args()
    net = nw.BatchedModel()
    print(f"ONNX Runtime {ort.__version__}, numpy {np.__version__}; BatchedModel batched: {net.batched} {net.reason}")
    print(f"load: {os.getloadavg()[0]:.1f} (1-min load average at start)")
    rng = np.random.default_rng(0)
    h = rng.uniform(-0.9, 0.9, (net.copies, 2, 1, 1, 200)).astype(np.float32)
    for rows in (1, 2, a.rows):
        fns = candidates(net, rows, not a.no_numpy)
        x = nw.probe(net.copies, rows, seed=rows)
        calls = a.calls if rows <= 2 else max(3, a.calls * 2 // rows)
        res = time_calls(fns, x, h, calls, a.reps)
        unit, per = ("µs per call", 1.0) if rows <= 2 else ("µs per row", float(rows))
        print_table(f"T = {rows} rows, 4 copies ({a.reps} reps × {calls} calls)", res, "published 1 copy", per, unit)
    exactness(net, candidates(net, 1, not a.no_numpy), 2000)
    if a.trial:
        trial_exactness(net, candidates(net, 1, not a.no_numpy), a.trial, a.steps)
    rotation_check(a.trial, a.reps)
    print(f"load: {os.getloadavg()[0]:.1f} (1-min load average at the end)")
    return 0


if __name__ == "__main__":
    sys.exit(main())
