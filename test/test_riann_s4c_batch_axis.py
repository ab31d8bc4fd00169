"""riann_ros/estimators/riann/s4c_batch_axis.py: the batch edit of the published model changes its declared shapes
and nothing else."""

from __future__ import annotations

from riann_ros.estimators.riann import default_model_path
from riann_ros.estimators.riann.s4b_model import _session
from riann_ros.estimators.riann.s4c_batch_axis import GRAPH_INPUT, GRAPH_OUTPUT, MODEL_GRAPH, batch_model, fields


def _graph(model: bytes) -> dict[int, list[bytes]]:
    """The graph's fields by number (1 nodes, 5 initializers, 11 inputs, 12 outputs, ...)."""
    graph = next(p for n, _, p in fields(model) if n == MODEL_GRAPH)
    out: dict[int, list[bytes]] = {}
    for n, _, p in fields(graph):
        out.setdefault(n, []).append(p)
    return out


def test_the_batch_edit_changes_only_the_declared_shapes():
    raw = default_model_path().read_bytes()
    edited = batch_model(raw)
    a, b = _graph(raw), _graph(edited)
    assert a.keys() == b.keys()
    assert a[GRAPH_INPUT] != b[GRAPH_INPUT] and a[GRAPH_OUTPUT] != b[GRAPH_OUTPUT]
    assert all(a[k] == b[k] for k in a if k not in (GRAPH_INPUT, GRAPH_OUTPUT))  # nodes, weights: the same bytes
    assert [n for n, _, _ in fields(raw)] == [n for n, _, _ in fields(edited)]
    s = _session(edited, 1)
    shapes = {v.name: v.shape for v in (*s.get_inputs(), *s.get_outputs())}
    assert shapes["input"] == ["batch", "sequence", 7]
    assert shapes["h0"] == [2, 1, "batch", 200]
    assert shapes["output"] == ["batch", "sequence", 4]
    assert batch_model(edited) == edited
