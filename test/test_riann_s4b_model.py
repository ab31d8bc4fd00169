"""riann_ros/estimators/riann/s4b_model.py: the ensemble's copies in one call mean the same as the published model run
once per copy."""

from __future__ import annotations

import functools
import importlib.resources
from pathlib import Path

import numpy as np
import onnxruntime as ort
import pytest

from riann_ros.estimators.riann import default_model_path
from riann_ros.estimators.riann import s4b_model as network
from riann_ros.estimators.riann.s4a_ensemble import frames, rotate_rows
from riann_ros.estimators.riann.s4b_model import BatchedModel, _session, open_model, probe
from riann_ros.estimators.riann.s4c_batch_axis import GRAPH_INPUT, MODEL_GRAPH, batch_model, map_field

TOL = 1e-6


@pytest.fixture(scope="module")
def net() -> BatchedModel:
    return BatchedModel()


def _diff(a: tuple[np.ndarray, np.ndarray], b: tuple[np.ndarray, np.ndarray]) -> float:
    return max(float(np.abs(p - q).max()) for p, q in zip(a, b, strict=True))


@functools.cache
def _session_of_the_published_model() -> ort.InferenceSession:
    return open_model()[1]


def _published(x: np.ndarray, h: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The published session once per copy, written out here (not through BatchedModel)."""
    session = _session_of_the_published_model()
    out = np.empty((len(x), x.shape[1], 4), np.float32)
    hn = np.empty_like(h)
    for m in range(len(x)):
        o, hn[m] = session.run(["output", "hn"], {"input": x[m : m + 1], "h0": h[m]})
        out[m] = o[0]
    return out, hn


def _ensemble_rows(acc: np.ndarray, gyr: np.ndarray, dt: float, copies: int = 4) -> np.ndarray:
    """The rows the ensemble feeds its copies: the IMU in each copy's rotated frame, float32."""
    x = np.column_stack([acc, gyr, np.full(len(acc), dt)])
    return np.stack([x if m == 0 else rotate_rows(x, r) for m, r in enumerate(frames(copies))]).astype(np.float32)


def test_weights_come_from_the_riann_package():
    p = default_model_path()
    assert p == importlib.resources.files("riann") / "riann.onnx"
    assert isinstance(p, Path) and p.is_file()


def test_the_published_model_runs_batched(net):
    assert net.batched, net.reason
    assert net.copies == 4
    assert net.fresh_state().shape == (4, 2, 1, 1, 200)
    assert net.fresh_state().dtype == np.float32


@pytest.mark.parametrize("rows", [1, 2, 3, 5, 300])
def test_equals_the_published_model_per_copy_on_synthetic_rows(net, rows):
    x = probe(4, rows, seed=rows)
    h = np.random.default_rng(rows).uniform(-0.9, 0.9, (4, 2, 1, 1, 200)).astype(np.float32)
    got = net.run(x, h)
    assert got[0].shape == (4, rows, 4) and got[1].shape == (4, 2, 1, 1, 200)
    assert _diff(got, _published(x, h)) <= TOL


def test_longer_than_a_chunk_carries_the_state_across_chunks(net, monkeypatch):
    """A call longer than CHUNK runs in equal chunks and gives what the published model gives in one call. (The
    chunks are long because ONNX Runtime's output layer rounds differently in calls of up to 64 rows; 100 here
    gives chunks of 84 rows, CHUNK itself thousands.)"""
    monkeypatch.setattr(network, "CHUNK", 100)  # the same code as with CHUNK rows, quicker
    x = probe(4, 3 * 100 + 37, seed=11)
    h = net.fresh_state()
    got = net.run(x, h)
    assert _diff(got, _published(x, h)) <= TOL


def test_calls_of_any_length_equal_the_published_model_called_alike(net):
    """The state is carried between calls of uneven length exactly as the published model carries it."""
    x = probe(4, 300, seed=12)
    h = hp = net.fresh_state()
    for a, b in [(0, 1), (1, 3), (3, 7), (7, 100), (100, 101), (101, 300)]:
        (o, h), (op, hp) = net.run(x[:, a:b], h), _published(x[:, a:b], hp)
        assert _diff((o, h), (op, hp)) <= TOL
    assert _diff((h,), (_published(x, net.fresh_state())[1],)) <= TOL  # the state as after one call


def _row_by_row(run, x: np.ndarray, h: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """``run`` called once per row, the state carried from call to call."""
    out = np.empty((len(x), x.shape[1], 4), np.float32)
    for t in range(x.shape[1]):
        o, h = run(x[:, t : t + 1], h)
        out[:, t] = o[:, 0]
    return out, h


def test_one_row_at_a_time_carries_the_state_between_calls(net):
    rng = np.random.default_rng(3)
    n = 400
    acc = np.array([0.5, -1.0, 9.6]) + rng.normal(0, 1.5, (n, 3))
    gyr = np.cumsum(rng.normal(0, 0.2, (n, 3)), axis=0)
    x = _ensemble_rows(acc, gyr, 0.005)
    got = _row_by_row(net.run, x, net.fresh_state())
    assert _diff(got, _row_by_row(_published, x, net.fresh_state())) <= TOL
    assert _diff((got[1],), (_published(x, net.fresh_state())[1],)) <= TOL  # the state as after one call


@pytest.mark.parametrize("copies", [4, 1])
def test_run_leaves_its_arguments_and_earlier_results_alone(copies):
    net = BatchedModel(copies=copies)
    x = probe(copies, 1, seed=2)
    h = net.fresh_state()
    x0, h0 = x.copy(), h.copy()
    a = net.run(x, h)
    a0 = (a[0].copy(), a[1].copy())
    net.run(probe(copies, 1, seed=9), a[1])  # the same bound buffers again
    assert np.array_equal(x, x0) and np.array_equal(h, h0)
    assert np.array_equal(a[0], a0[0]) and np.array_equal(a[1], a0[1])


def test_zero_rows_and_one_copy(net):
    h = np.random.default_rng(0).uniform(-0.5, 0.5, (4, 2, 1, 1, 200)).astype(np.float32)
    out, hn = net.run(np.zeros((4, 0, 7), np.float32), h)
    assert out.shape == (4, 0, 4) and np.array_equal(hn, h) and hn is not h
    one = BatchedModel(copies=1)
    assert one.batched
    x = probe(1, 3, seed=4)
    assert _diff(one.run(x, h[:1]), _published(x, h[:1])) <= TOL


def test_bad_shapes_and_copies_are_refused(net):
    with pytest.raises(ValueError, match=r"input rows must have shape \(4, T, 7\)"):
        net.run(np.zeros((3, 1, 7), np.float32), net.fresh_state())
    with pytest.raises(ValueError, match="state must have shape"):
        net.run(np.zeros((4, 1, 7), np.float32), np.zeros((4, 2, 200), np.float32))
    with pytest.raises(ValueError, match="copies must be at least 1"):
        BatchedModel(copies=0)


def test_a_missing_model_file_is_a_clear_error(tmp_path):
    with pytest.raises(FileNotFoundError, match="RIANN model not found"):
        BatchedModel(tmp_path / "nope.onnx")


def test_a_file_that_is_not_a_model_is_a_clear_error(tmp_path):
    bad = tmp_path / "bad.onnx"
    bad.write_bytes(b"this is not a protobuf")
    with pytest.raises(ValueError, match="not a loadable ONNX model"):
        BatchedModel(bad)


def _rename(model: bytes, old: bytes, new: bytes) -> bytes:
    """The model with the graph input ``old`` renamed, in its declaration and in every node that reads it."""

    def graph(g: bytes) -> bytes:
        g = map_field(g, GRAPH_INPUT, lambda vi: map_field(vi, 1, lambda name: new if name == old else name))
        return map_field(g, 1, lambda node: map_field(node, 1, lambda name: new if name == old else name))

    return map_field(model, MODEL_GRAPH, graph)


def test_a_model_with_other_inputs_is_not_a_riann_model(tmp_path):
    raw = default_model_path().read_bytes()
    wrong = tmp_path / "wrong.onnx"
    wrong.write_bytes(_rename(raw, b"h0", b"state"))  # a valid model, with another name for its state input
    assert _session(str(wrong), 1).get_inputs()[1].name == "state"
    with pytest.raises(ValueError, match=r"is not a RIANN-compatible model: inputs \['input', 'state'\]"):
        BatchedModel(wrong)


def test_a_model_with_a_symbolic_batch_runs_batched(tmp_path):
    path = tmp_path / "batched.onnx"
    path.write_bytes(batch_model(default_model_path().read_bytes()))
    net = BatchedModel(path)
    assert net.batched, net.reason
    assert net.fresh_state().shape == (4, 2, 1, 1, 200)
    x = probe(4, 3, seed=5)
    h = net.fresh_state()
    assert _diff(net.run(x, h), _published(x, h)) <= TOL


def test_a_model_that_fails_the_probe_runs_copy_by_copy(monkeypatch):
    """The safety net: when the batched model does not agree with the published one on the load-time probe
    (here: a tolerance no run can meet), every call runs the published session once per copy."""
    monkeypatch.setattr(network, "PROBE_TOL", -1.0)
    net = BatchedModel()
    assert not net.batched and "differs from the published one" in net.reason
    for rows in (1, 3):
        x = probe(4, rows, seed=rows)
        h = np.random.default_rng(rows).uniform(-0.9, 0.9, (4, 2, 1, 1, 200)).astype(np.float32)
        assert _diff(net.run(x, h), _published(x, h)) == 0.0


@pytest.mark.broad
@pytest.mark.slow
def test_equals_the_published_model_on_a_whole_broad_trial(net, broad_trial):
    """Trial 07 (fast rotation) as the ensemble feeds it: the whole trial in one call, then its first 3000 rows
    one call each, against the published model run copy by copy."""
    rec = broad_trial("07")
    dt = float(np.median(np.diff(rec.stamps_ns))) * 1e-9
    x = _ensemble_rows(rec.acc, rec.gyr, dt)
    h = net.fresh_state()
    want = _published(x, h)
    got = net.run(x, h)
    assert _diff(got, want) <= TOL
    n = 3000
    got = _row_by_row(net.run, x[:, :n], h)
    assert _diff(got, _row_by_row(_published, x[:, :n], h)) <= TOL
    assert _diff((got[1],), (_published(x[:, :n], h)[1],)) <= TOL
