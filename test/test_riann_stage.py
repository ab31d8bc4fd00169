"""riann_ros/estimators/riann/stage.py: the one interface every stage satisfies, and the restart table (docs/riann.md
shows it, and each of its entries holds for its stage)."""

from __future__ import annotations

import inspect
import typing

import numpy as np
import pytest
from helpers_riann import field_rows, swinging_stream

from conftest import ROOT
from riann_ros.estimators.riann import RiannEstimator
from riann_ros.estimators.riann import stage as stage_module
from riann_ros.estimators.riann.s2_grid import DirectRows
from riann_ros.estimators.riann.s4b_model import BatchedModel
from riann_ros.estimators.riann.stage import RESTARTS, Cause, Samples, first_step, restart_table


@pytest.fixture(scope="module")
def model():
    return BatchedModel(copies=4)


def _busy(model: BatchedModel) -> RiannEstimator:
    """An estimator that has run a swinging stream with a gyro bias, a hole and a field."""
    x, dt = swinging_stream(800, jitter=False)
    est = RiannEstimator(model=model, mag_calibration=False)  # (the calibration is kept over a reset: by design)
    est._run([(*r[:3], r[3] + 0.05, r[4], r[5]) for r in x], dt, field_rows(len(x)))
    assert est.network.holes == 1 and est.heading.mag.started and abs(est.bias.bias[0]) > 1e-3
    return est


def test_docs_show_the_restart_table_of_the_code():
    doc = (ROOT / "docs" / "riann.md").read_text()
    assert restart_table() in doc


def test_every_stage_of_the_chain_has_its_row_for_every_cause(model):
    est = RiannEstimator(model=model)
    assert [s.NAME for s in est.stages] == list(RESTARTS)
    assert len(est.stages) == 8  # stage 8 included
    for what in RESTARTS.values():
        assert set(what) == set(Cause)


def test_every_stage_runs_one_record_into_one_record(model):
    """The Stage protocol: ``run(block)`` with one argument, annotated with the records of stage.py (never a bare
    tuple), ``restart(cause)`` and ``diagnostics()``."""
    records = {n for n, v in vars(stage_module).items() if isinstance(v, type) and issubclass(v, tuple)}
    for s in [*RiannEstimator(model=model).stages, DirectRows()]:
        hints = typing.get_type_hints(type(s).run, vars(stage_module))
        params = list(inspect.signature(s.run).parameters)
        assert params == ["block"], type(s)
        assert hints["block"].__name__ in records and hints["return"].__name__ in records, (type(s), hints)
        assert list(inspect.signature(s.restart).parameters) == ["cause"]
        assert isinstance(s.diagnostics(), dict)


def test_a_gap_does_what_the_table_says(model):
    est = _busy(model)
    tl, steps = est.timeline, est.timeline.steps
    step, n_steps, n_clock = steps.step, len(steps._dts), len(tl.clock._long)
    bias, psi, rows, holes = est.bias.bias, est.heading.psi, est.network.rows, est.network.holes
    est.on_gap()
    # timeline: a new timeline from 0 whose first step is not counted; statistics kept; the model's window cleared
    assert len(tl.model._t) == 0
    x, _ = swinging_stream(4, jitter=False)
    assert tl.run(Samples.of(x[:1], [0.5])).t_ns == [0.0]
    assert steps.step == step and len(steps._dts) == n_steps and len(tl.clock._long) == n_clock
    # grid: history cleared
    assert len(est.grid.hist) == 0
    # bias: kept
    assert est.bias.bias == bias
    # network: a fresh state, the counts kept
    assert not est.network._h.any() and (est.network.rows, est.network.holes) == (rows, holes)
    # carry: from the fresh network's first output
    assert est.carry.q_net is None
    # handover: no blend; a gap's fresh network, whose σ goes to stage 8
    assert est.handover.blend is None and est.handover.fresh is not None
    # heading: kept, re-acquired without a bridge
    assert est.heading.psi == psi and est.heading.mag.s.reacq and est.heading.mag.s.weight == 0.0
    # uncertainty: the rate low-pass starts again, the heading unknown until a field sets it
    assert not est.uncertainty.started and not est.uncertainty.known and est.uncertainty.spread == 0.0


def test_a_reset_does_what_the_table_says(model):
    est = _busy(model)
    est.reset()
    assert est.timeline.steps is None and len(est.grid.hist) == 0 and est.bias.fe is None
    assert not est.network._h.any() and est.network.rows == est.network.holes == 0
    assert est.carry.q_net is None and est.handover.blend is None and est.handover.fresh is None
    assert est.heading.psi == 0.0 and est.heading.q_prev is None and not est.heading.mag.started
    assert est.uncertainty.last is None
    assert est.diagnostics() == RiannEstimator(model=model, mag_calibration=False).diagnostics()
    # anew: what a reset estimator outputs and reports is what a new one does
    x, dt = swinging_stream(600, seed=3)
    mag = field_rows(len(x))
    q = est._run(x, dt, mag)
    fresh = RiannEstimator(model=model, mag_calibration=False)
    q_new = fresh._run(x, dt, mag)
    assert np.array_equal(q, q_new)
    assert np.array_equal(est.sigma(np.ones(len(x))), fresh.sigma(np.ones(len(x))))
    assert est.diagnostics() == fresh.diagnostics()


@pytest.mark.parametrize(("dt", "want"), [(0.005, 0.005), (0.0, 0.01), (-1.0, 0.01), (1e-6, 0.01), (20.0, 0.01),
                                          (float("nan"), 0.01)])
def test_a_first_step_outside_its_range_is_the_fallback(dt, want):
    assert first_step(dt) == want
