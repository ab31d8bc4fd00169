"""RIANN's stages one by one (riann_ros/estimators/riann/): a block equals its samples one at a time, the plain-float
forms equal the vectorised ones, and each stage restarts as the restart table says (and docs/riann.md shows it)."""

from __future__ import annotations

import math

import numpy as np
import pytest

from conftest import ROOT
from riann_ros.estimators.riann import RiannEstimator
from riann_ros.estimators.riann.s1_timeline import Timeline
from riann_ros.estimators.riann.s2_grid import Grid
from riann_ros.estimators.riann.s3_bias import BATCH_ROWS, Bias
from riann_ros.estimators.riann.s4_network import Network
from riann_ros.estimators.riann.s4b_model import BatchedModel
from riann_ros.estimators.riann.s5_carry import SCALAR_MAX, Carry
from riann_ros.estimators.riann.s6_handover import Handover
from riann_ros.estimators.riann.s7_heading import Heading
from riann_ros.estimators.riann.s7a_mag import MagHeading
from riann_ros.estimators.riann.stage import RESTARTS, Cause, GridBlock, Hole, restart_table
from riann_ros.rotations import from_rotvec, normalized

G = 9.81


@pytest.fixture(scope="module")
def model():
    return BatchedModel(copies=4)


def _stream(n: int, seed: int = 0, jitter: bool = True) -> tuple[list[tuple[float, ...]], list[float]]:
    """A swinging sensor: samples (acc, gyr) and steps (s), jittery or at 10 ms, with one 0.3 s hole."""
    rng = np.random.default_rng(seed)
    dt = rng.uniform(0.003, 0.012, n) if jitter else np.full(n, 0.010)
    dt[n // 2] = 0.3
    t = np.cumsum(dt)
    roll = 0.6 * np.sin(2.0 * np.pi * 0.8 * t)
    acc = np.column_stack([0.3 * np.sin(5 * t), G * np.sin(roll), G * np.cos(roll)]) + rng.normal(0, 0.05, (n, 3))
    gyr = np.column_stack([0.6 * 2 * np.pi * 0.8 * np.cos(2 * np.pi * 0.8 * t), 0.2 * np.sin(t), 0.1 + 0 * t])
    return [tuple(r) for r in np.column_stack([acc, gyr]).tolist()], dt.tolist()


def _mag(n: int) -> list[tuple[float, float, float] | None]:
    return [None if k % 7 == 3 else (20e-6, 5e-6 * math.sin(k / 50), -40e-6) for k in range(n)]


# -- the restart table --------------------------------------------------------------------------------------------
def test_docs_show_the_restart_table_of_the_code():
    doc = (ROOT / "docs" / "riann.md").read_text()
    assert restart_table() in doc


def test_every_stage_says_what_it_does_on_every_restart(model):
    est = RiannEstimator(model=model)
    names = [s.NAME for s in est.stages]
    assert names == list(RESTARTS)
    for what in RESTARTS.values():
        assert set(what) == set(Cause)


# -- a block equals its samples one at a time ----------------------------------------------------------------------
def test_timeline_block_equals_samples():
    x, dt = _stream(3000)
    whole = Timeline(0.1, "auto").run(x, dt)
    one = Timeline(0.1, "auto")
    parts = [one.run([xk], [d]) for xk, d in zip(x, dt, strict=True)]
    assert whole.t == [p.t[0] for p in parts]
    assert whole.spec == [p.spec[0] for p in parts]
    assert whole.switched == [p.switched[0] for p in parts]
    assert [h.index for h in whole.holes] == [k for k, p in enumerate(parts) if p.holes] == [1500]


@pytest.mark.parametrize("jitter", [True, False])
def test_grid_block_equals_samples(jitter):
    """Jittery stamps (no sample delay once judged jittery, after 16 steps) and a regular 100 Hz stream (up-sampled,
    read a quarter step early)."""
    x, dt = _stream(2000, jitter=jitter)
    tl = Timeline(0.1, "auto").run(x, dt)
    assert {s[4] for s in tl.spec} == ({0.0} if jitter else {0.0, 0.0025})
    whole = Grid().run(x, tl)
    grid = Grid()
    rows, steps, forks, r0, r1 = [], [], [], [], []
    for k in range(len(x)):
        sub = type(tl)(t=tl.t[k:k + 1], spec=tl.spec[k:k + 1], start=tl.start[k:k + 1],
                       switched=tl.switched[k:k + 1], holes=[Hole(0, h.seconds, h.w_before, h.w_after)
                                                             for h in tl.holes if h.index == k])
        g = grid.run(x[k:k + 1], sub)
        forks += [(len(rows) + p, s) for p, s in g.forks]
        r0.append(len(rows) + g.r0[0])
        r1.append(len(rows) + g.r1[0])
        rows += g.rows
        steps += g.steps
        assert np.allclose(g.g_delta[0], whole.g_delta[k], rtol=0, atol=1e-9)
        assert np.allclose(g.g_carry[0], whole.g_carry[k], rtol=0, atol=1e-9)
    assert rows == whole.rows and steps == whole.steps and forks == whole.forks
    assert r0 == whole.r0 and r1 == whole.r1
    assert len(whole.forks) == 1 and len(rows) > 2000  # up-sampled to the grid


def test_bias_block_equals_rows():
    x, _ = _stream(600, jitter=False)
    rows = [(*r[:3], r[3] + 0.05, r[4] - 0.03, r[5]) for r in x]
    steps = [0.005] * 300 + [0.004] * 300  # a grid-step switch in the block
    whole, before = Bias(True, 8.0, 3.0).run(rows, steps)
    one = Bias(True, 8.0, 3.0)
    got = [one.run([r], [s]) for r, s in zip(rows, steps, strict=True)]
    assert len(rows) >= BATCH_ROWS
    assert np.allclose([g[0][0] for g in got], whole, atol=1e-12)
    assert np.allclose([g[1][0] for g in got], before[:-1], atol=1e-12)
    assert np.abs(np.array(before[-1])).max() > 0.0  # it learned something


def test_network_block_equals_rows_across_a_fork(model):
    x, _ = _stream(300, jitter=False)
    rows = [(*r, 0.005) for r in x]
    forks = [(120, 0.005)]
    whole = Network(model, 0.0).run(rows, forks)
    net = Network(model, 0.0)
    one = np.vstack([net.run(rows[k:k + 1], [(0, 0.005)] if k == 120 else []) for k in range(len(rows))])
    assert np.abs(one - whole).max() < 1e-6
    # after the fork the output is a fresh network's, from the row after the first one it ran beside the old one
    fresh = Network(model, 0.0).run(rows[120:], [])
    assert np.abs(whole[121:] - fresh[1:]).max() < 1e-6
    assert np.abs(whole[121:131] - Network(model, 0.0).run(rows, [])[121:131]).max() > 1e-3


def _carry_input(n: int, seed: int) -> tuple[np.ndarray, GridBlock, list]:
    rng = np.random.default_rng(seed)
    net = np.array([normalized(tuple(q)) for q in rng.normal(size=(n, 4))])
    r1 = np.sort(rng.integers(0, n, n))
    r1[0] = max(r1[0], 1)
    r0 = np.concatenate([[0], r1[:-1]])
    vec = [tuple(v) for v in rng.normal(size=(n, 3)).tolist()]
    s = rng.uniform(0.0, 0.01, n)
    s[::4] = 0.0
    g = GridBlock(r0=r0.tolist(), r1=r1.tolist(), g_delta=vec, s_delta=s.tolist(), g_carry=vec[::-1],
                  s_carry=s[::-1].tolist())
    bias = [tuple(v) for v in (0.01 * rng.normal(size=(n + 1, 3))).tolist()]
    return net, g, bias


def test_carry_plain_floats_equal_the_vectorised_form():
    net, g, bias = _carry_input(40, 1)
    vec_qc, vec_d = Carry().run(net, g, bias)
    one = Carry()
    for k in range(len(g.r0)):
        gk = GridBlock(r0=g.r0[k:k + 1], r1=g.r1[k:k + 1], g_delta=g.g_delta[k:k + 1], s_delta=g.s_delta[k:k + 1],
                       g_carry=g.g_carry[k:k + 1], s_carry=g.s_carry[k:k + 1])
        qc, d = one.run(net, gk, bias)
        assert len(gk.r0) <= SCALAR_MAX
        assert np.allclose(qc[0], vec_qc[k], atol=1e-12) and np.allclose(d[0], vec_d[k], atol=1e-12)


def test_handover_block_equals_samples():
    rng = np.random.default_rng(2)
    n = 400
    qc = [normalized(tuple(q)) for q in (np.array([1.0, 0, 0, 0]) + 0.2 * rng.normal(size=(n, 4))).tolist()]
    delta = [from_rotvec(*v) for v in (0.01 * rng.normal(size=(n, 3))).tolist()]
    acc = [tuple(v) for v in (np.array([0.0, 0.0, G]) + rng.normal(size=(n, 3))).tolist()]
    holes = [Hole(50, 0.3, (1.0, 0.0, 0.0), (0.0, 2.0, 0.0)), Hole(200, 0.2, (0.1, 0.0, 0.0), (0.1, 0.0, 0.0))]
    q_all, sd_all, br_all = Handover(True).run(list(qc), delta, [0.01] * n, acc, holes)
    one = Handover(True)
    for k in range(n):
        hk = [Hole(0, h.seconds, h.w_before, h.w_after) for h in holes if h.index == k]
        q, sd, br = one.run([qc[k]], [delta[k]], [0.01], [acc[k]], hk)
        assert q[0] == q_all[k] and sd[0] == sd_all[k]
        assert br == ({0: br_all[k]} if k in br_all else {})
    assert sd_all[50] > 0.0 and q_all[60] != qc[60]  # the hand-over ran


def test_heading_plain_floats_equal_the_vectorised_form():
    rng = np.random.default_rng(3)
    n = 600
    qc = [normalized(tuple(q)) for q in (np.array([1.0, 0.1, 0, 0]) + 0.05 * rng.normal(size=(n, 4))).tolist()]
    delta = [from_rotvec(*v) for v in (0.02 * rng.normal(size=(n, 3))).tolist()]
    mag = [None] * 100 + _mag(n - 100)
    bridges = {300: 5.0}
    sd = [0.0] * n
    vec = Heading(MagHeading(9.0, 0.0, True)).run(qc, delta, [0.01] * n, mag, bridges, sd)
    one = Heading(MagHeading(9.0, 0.0, True))
    got = np.vstack([one.run([qc[k]], [delta[k]], [0.01], [mag[k]], {0: 5.0} if k == 300 else {}, [0.0])
                     for k in range(n)])
    assert np.abs(got - vec).max() < 1e-9
    assert one.mag.started


@pytest.mark.slow
@pytest.mark.parametrize("jitter", [True, False])
def test_estimator_block_equals_samples(model, jitter):
    x, dt = _stream(1500, jitter=jitter)
    mag = _mag(len(x))
    a = np.array([r[:3] for r in x])
    g = np.array([r[3:] for r in x])
    m = np.array([v if v is not None else (np.nan,) * 3 for v in mag])
    whole = RiannEstimator(model=model).update_batch(a, g, dt, m)
    est = RiannEstimator(model=model)
    one = np.vstack([est.update(a[k], g[k], dt[k], m[k]) for k in range(len(x))])
    assert np.abs(one - whole).max() < 1e-5
    assert est.network.holes == 1


# -- restarts ---------------------------------------------------------------------------------------------------
def test_a_gap_keeps_bias_rate_and_heading_and_a_reset_forgets_them(model):
    x, dt = _stream(800, jitter=False)
    est = RiannEstimator(model=model)
    est._run([(*r[:3], r[3] + 0.05, r[4], r[5]) for r in x], dt, None)
    bias, step, psi = est.bias.bias, est.timeline.steps.step, est.heading.psi
    assert abs(bias[0]) > 1e-3
    est.on_gap()
    assert est.bias.bias == bias and est.timeline.steps.step == step and est.heading.psi == psi
    assert len(est.grid.hist) == 0 and est.carry.q_net is None
    assert est.timeline.run(x[:1], [0.5]).t == [0.0]  # a new timeline; the gap's step is not an input step
    assert est.timeline.steps.step == step
    est.reset()
    assert est.bias.bias == (0.0, 0.0, 0.0) and est.timeline.steps is None and est.heading.psi == 0.0


def test_after_a_hole_the_stages_act_at_the_hole(model):
    x, dt = _stream(1200, jitter=False)
    est = RiannEstimator(model=model)
    tl = est.timeline.run(x, dt)
    assert [h.index for h in tl.holes] == [600]
    g = est.grid.run(x, tl)
    assert g.forks == [(g.r1[600], tl.spec[600][0])]  # the fresh state starts after the hole sample's rows
    rows, _ = est.bias.run(g.rows, g.steps)
    est.network.run(rows, g.forks)
    assert est.network.holes == 1


# -- the sample delay (stage 1 says it, stage 2 reads the samples that much earlier) -------------------------------
def _regular(rate: float, n: int = 400) -> tuple[list[tuple[float, ...]], list[float]]:
    """A regular stream: acc and gyr linear in time (gyr x = 0.5 + 0.1 t rad/s), ``n`` samples at ``rate``."""
    t = np.arange(n) / rate
    rows = np.column_stack([0 * t, 0 * t, G + 0 * t, 0.5 + 0.1 * t, 0 * t, 0 * t])
    return [tuple(r) for r in rows.tolist()], [1.0 / rate] * n


@pytest.mark.parametrize(("rate", "model", "delay", "want"), [
    (50.0, "auto", 0.25, 0.005),  # up-sampled ×4: a quarter of 20 ms
    (25.0, "auto", 0.5, 0.020),
    (200.0, "auto", 0.25, 0.0),  # fed straight in: no delay
    (50.0, "points", 0.25, 0.0),  # a set model: as set
    (50.0, "means", 0.25, 0.0),
    (50.0, "auto", 0.0, 0.0),
])
def test_timeline_says_the_sample_delay_of_an_up_sampled_regular_stream_only(rate, model, delay, want):
    x, dt = _regular(rate)
    tl = Timeline(0.1, model, delay).run(x, dt)
    delays = np.array([s[4] for s in tl.spec])
    assert not delays[:16].any()  # none before the stream is judged regular (16 steps)
    np.testing.assert_allclose(delays[16:], want, rtol=0, atol=1e-12)


def test_timeline_gives_jittery_sample_times_no_delay_and_a_clock_its_delay():
    """Random sample times: none (the sample-model test says what they are); a 50 Hz clock stamped on arrival
    (0-10 ms late): a quarter of its period once the clock test has recognised it."""
    x, dt = _stream(3000)
    assert Timeline(0.1, "auto").run(x, dt).spec[-1][4] == 0.0
    rng = np.random.default_rng(1)
    n = 1500
    stamps = np.arange(n) * 0.020 + rng.uniform(0.0, 0.010, n)
    xs, _ = _regular(50.0, n)
    tl = Timeline(0.1, "auto").run(xs, np.diff(stamps, prepend=-0.02).tolist())
    assert tl.spec[100][4] == 0.0  # jittery until the clock test has seen 256 steps
    assert tl.spec[-1][4] == pytest.approx(0.005, rel=1e-3)


def test_grid_reads_a_delayed_sample_as_the_signal_that_much_before_its_stamp():
    """Regular 50 Hz point samples of a ramp read a quarter step (5 ms) early: the rows (5 ms grid) are the ramp's
    means over the cells centred on the grid points of the shifted timeline, made as soon as the signal time reaches
    a cell's end; the newest row is carried to the stamp (half a cell on the signal, then the newest sample held
    over the 5 ms); from stamp to stamp the gyro is the signal between the two signal times less the previous carry
    plus the new one (the carries and the steps add up)."""
    x, dt = _regular(50.0, 200)
    g = Grid().run(x, Timeline(0.1, "auto", 0.25).run(x, dt))  # the delay from sample 16 on (judged regular)
    tau = 0.005 * np.arange(len(g.rows))  # the first grid point on the first sample
    rows = np.array(g.rows)
    later = np.arange(len(rows)) >= g.r0[20]
    np.testing.assert_allclose(rows[later, 3], 0.5 + 0.1 * (tau[later] + 0.005), atol=1e-9)
    for k in range(20, 200):
        assert g.r1[k] - g.r0[k] == 4 and tau[g.r1[k] - 1] == pytest.approx(k / 50 - 0.010, abs=1e-9)
        assert g.s_carry[k] == pytest.approx(0.010, abs=1e-9)
        on_signal = 0.5 + 0.1 * (k / 50 - 0.0025)  # the ramp's mean over the half cell before the signal time
        assert g.g_carry[k][0] == pytest.approx(0.5 * (on_signal + 0.5 + 0.1 * k / 50), abs=1e-9)
        w_prev, w = 0.5 + 0.1 * (k - 1) / 50, 0.5 + 0.1 * k / 50
        want = 0.5 * (w_prev + w) * 0.020 - w_prev * 0.005 + w * 0.005
        assert g.g_delta[k][0] * g.s_delta[k] == pytest.approx(want, abs=1e-9)
