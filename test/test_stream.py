"""The ROS-free input gate and EstimatorStream: every documented bad-input rule."""

from __future__ import annotations

import numpy as np
import pytest

from riann_ros import gate as gt
from riann_ros.estimators import create
from riann_ros.gate import GateConfig, InputGate
from riann_ros.stream import EstimatorStream

A = (0.0, 0.0, 9.81)
G = (0.0, 0.0, 0.0)
S = 1_000_000_000


def test_first_sample_uses_nominal_rate_then_stamp_differences():
    gate = InputGate(GateConfig(nominal_rate=200.0))
    r0 = gate.check(S, A, G)
    assert r0.accepted and r0.reset == gt.START and r0.dt == pytest.approx(0.005)
    r1 = gate.check(S + 3_000_000, A, G)
    assert r1.accepted and r1.reset is None and r1.dt == pytest.approx(0.003)


@pytest.mark.parametrize(("acc", "gyr", "reason"), [
    ((np.nan, 0.0, 9.8), G, gt.NON_FINITE),
    (A, (0.0, np.inf, 0.0), gt.NON_FINITE),
    ((3000.0, 0.0, 0.0), G, gt.OUT_OF_RANGE),
    (A, (0.0, 0.0, 250.0), gt.OUT_OF_RANGE),
    ((1e200, 0.0, 0.0), G, gt.OUT_OF_RANGE),  # finite but overflows when squared
])
def test_bad_samples_are_rejected_without_touching_the_stamp_sequence(acc, gyr, reason):
    gate = InputGate()
    gate.check(S, A, G)
    r = gate.check(S + 10_000_000, acc, gyr)
    assert not r.accepted and r.reason == reason and gate.rejected[reason] == 1
    nxt = gate.check(S + 20_000_000, A, G)
    assert nxt.accepted and nxt.dt == pytest.approx(0.02)  # dt from the last accepted sample


def test_repeats_backwards_gaps_and_clock_jumps():
    gate = InputGate(GateConfig(max_dt=0.5))
    gate.check(S, A, G)
    assert gate.check(S, A, G).reason == gt.STAMP_REPEAT
    assert gate.check(S - 1_000_000, A, G).reason == gt.STAMP_BACKWARDS
    r = gate.check(S + 2 * S, A, G)  # 2 s later: gap
    assert r.accepted and r.reset == gt.GAP and r.dt == pytest.approx(0.01)
    r = gate.check(S, A, G)  # 2 s back: clock jump (bag loop)
    assert r.accepted and r.reset == gt.CLOCK_JUMP
    assert gate.resets[gt.GAP] == gate.resets[gt.CLOCK_JUMP] == 1


def test_zero_stamps_use_receive_time_and_warn_once():
    gate = InputGate()
    r = gate.check(0, A, G, receive_ns=5 * S)
    assert r.accepted and r.stamp_ns == 5 * S and r.warnings == [gt.ZERO_STAMP]
    r = gate.check(0, A, G, receive_ns=5 * S + 10_000_000)
    assert r.accepted and r.warnings == []
    assert gate.check(0, A, G).reason == gt.NO_STAMP  # offline: no receive time, nothing to use


def test_acc_in_g_warns_once_after_the_check_window():
    gate = InputGate()
    warned = []
    for i in range(200):
        warned += gate.check(S + i * 10_000_000, (0.0, 0.0, 1.0), G).warnings
    assert warned == [gt.ACC_IN_G]
    ok = InputGate()
    assert not any(ok.check(S + i * 10_000_000, A, G).warnings for i in range(200))


def test_acc_in_g_is_checked_anew_after_every_restart():
    """The verdict is the latest (re)start's: a driver restarted in m/s² (its clock jumps back) clears it, a relapse
    after that is warned about again; a gap or ~/reset re-checks too."""
    gate = InputGate()
    for i in range(60):
        gate.check(S + i * 10_000_000, (0.0, 0.0, 1.0), G)
    assert gate.acc_in_g and gate.acc_median == pytest.approx(1.0)
    warned = [w for i in range(60) for w in gate.check(S + i * 10_000_000, A, G).warnings]  # clock jump back
    assert warned == [] and not gate.acc_in_g and gate.acc_median == pytest.approx(np.linalg.norm(A))
    assert gate.resets[gt.CLOCK_JUMP] == 1
    t = S + 10 * S  # a gap: the check runs again, in g again: warned again
    warned = [w for i in range(60) for w in gate.check(t + i * 10_000_000, (0.0, 0.0, 1.0), G).warnings]
    assert warned == [gt.ACC_IN_G] and gate.acc_in_g
    gate.restart()  # ~/reset
    for i in range(49):
        gate.check(t + S + i * 10_000_000, A, G)
    assert gate.acc_in_g  # until the new window is complete, the last verdict stands
    gate.check(t + S + 49 * 10_000_000, A, G)
    assert not gate.acc_in_g


def test_dt_statistics_are_popped():
    gate = InputGate()
    for i in range(11):
        gate.check(S + i * 4_000_000, A, G)
    stats = gate.pop_dt_stats()
    assert stats["count"] == 11 and stats["max"] == pytest.approx(0.01) and stats["min"] == pytest.approx(0.004)
    assert gate.pop_dt_stats() == {"count": 0.0}


@pytest.mark.parametrize("name", ["riann", "madgwick", "mahony", "vqf"])
def test_process_batch_equals_per_sample_process(name):
    rng = np.random.default_rng(7)
    n = 400
    stamps = S + np.cumsum(rng.choice([0, 5_000_000, 10_000_000, -2_000_000, 900_000_000], n,
                                      p=[0.03, 0.8, 0.1, 0.04, 0.03])).astype(np.int64)
    acc = np.array(A) + rng.normal(0, 0.5, (n, 3))
    gyr = rng.normal(0, 0.3, (n, 3))
    acc[rng.integers(0, n, 5)] = np.nan
    batch = EstimatorStream(create(name), GateConfig(nominal_rate=200.0))
    q_b, ok = batch.process_batch(stamps, acc, gyr)
    single = EstimatorStream(create(name), GateConfig(nominal_rate=200.0))
    rows, sig = [], []
    for s, a, g in zip(stamps, acc, gyr, strict=True):
        rows.append(single.process(int(s), a, g)[0])
        sig.append(single.sigma)
    assert [r is not None for r in rows] == ok.tolist()
    tol = 1e-5 if name == "riann" else 1e-9  # RIANN: float32 GRU, one step at a time vs a sequence
    assert np.abs(np.array([r for r in rows if r is not None]) - q_b[ok]).max() < tol
    assert np.isnan(q_b[~ok]).all()
    # the σ of every accepted sample, the same on both paths (and NaN where rejected)
    assert [s is not None for s in sig] == ok.tolist()
    assert np.abs(np.array([s for s in sig if s is not None]) - batch.batch_sigma[ok]).max() < 1e-6
    assert np.isnan(batch.batch_sigma[~ok]).all() and (batch.batch_sigma[ok] > 0.0).all()
    assert batch.gate.rejected == single.gate.rejected and batch.gate.resets == single.gate.resets


def test_reset_restarts_the_stamp_sequence():
    s = EstimatorStream(create("riann"), GateConfig(nominal_rate=100.0))
    s.process(S, A, G)
    s.reset()
    q, r = s.process(S - 1_000_000, A, G)  # would be "backwards" without the reset
    assert q is not None and r.reset == gt.START


def test_batch_gate_fast_path_matches_per_sample_checks():
    rng = np.random.default_rng(11)
    n = 20000
    stamps = S + np.cumsum(rng.integers(4_000_000, 6_000_000, n)).astype(np.int64)
    acc = np.array(A) + rng.normal(0, 0.3, (n, 3))
    gyr = rng.normal(0, 0.2, (n, 3))
    stamps[12345] = stamps[12344]  # one repeat in the middle of a clean stretch
    acc[15000] = np.nan
    fast = InputGate(GateConfig(nominal_rate=200.0))
    slow = InputGate(GateConfig(nominal_rate=200.0))
    dts_fast = []
    i = 0
    while i < n:  # what process_batch does
        clean = fast.check_clean_prefix(stamps[i : i + 4096], acc[i : i + 4096], gyr[i : i + 4096])
        if len(clean):
            dts_fast += clean.tolist()
            i += len(clean)
            continue
        r = fast.check(int(stamps[i]), acc[i], gyr[i])
        if r.accepted:
            dts_fast.append(r.dt)
        i += 1
    dts_slow = [r.dt for r in (slow.check(int(s), a, g) for s, a, g in zip(stamps, acc, gyr, strict=True))
                if r.accepted]
    assert dts_fast == dts_slow and len(dts_fast) == n - 2
    assert fast.rejected == slow.rejected and fast.accepted == slow.accepted
    f, s = fast.pop_dt_stats(), slow.pop_dt_stats()
    assert f.keys() == s.keys() and all(abs(f[k] - s[k]) < 1e-12 for k in f)
