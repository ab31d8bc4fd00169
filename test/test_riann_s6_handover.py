"""riann_ros/estimators/riann/s6_handover.py: the hand-over from the gyro bridge to the fresh network after a hole."""

from __future__ import annotations

import math

import numpy as np
import pytest
from helpers_riann import G, hole_stream, shaken_with_a_hole

from riann_ros import quaternion as quat
from riann_ros.estimators.riann import RiannEstimator
from riann_ros.estimators.riann.s6_handover import TAU, Handover, HoleBlend, bridge_sigma
from riann_ros.estimators.riann.stage import CarryBlock, Cause, GridBlock, HandoverIn, Hole, Samples
from riann_ros.rotations import from_rotvec, normalized


def _q(rotvec: list[float]) -> tuple[float, float, float, float]:
    w, x, y, z = quat.from_rotvec(rotvec).tolist()
    return w, x, y, z


def test_bridge_sigma_grows_with_the_rate_change_and_the_rate_over_the_hole():
    assert bridge_sigma((0, 0, 0), (0, 0, 0), 0.4) == pytest.approx(1.0)
    steady = bridge_sigma((1.0, 0, 0), (1.0, 0, 0), 0.4)  # 1 rad/s through a 0.4 s hole
    assert steady == pytest.approx(math.hypot(1.0, math.degrees(0.25 * 0.4)))
    changed = bridge_sigma((1.0, 0, 0), (-1.0, 0, 0), 0.4)
    assert changed > steady
    assert bridge_sigma((1.0, 0, 0), (-1.0, 0, 0), 0.1) < changed


def test_weight_rises_toward_the_network_and_faster_at_rest_than_in_motion():
    q = _q([0.0, 0.0, 0.0])
    up = (0.0, 0.0, G)
    rest = HoleBlend(5.0, q, 0.0, up)
    moving = HoleBlend(5.0, q, 3.0, (6.0, 0.0, G))
    assert rest.weight() > 0.8 > 0.05 > moving.weight()
    k = []
    for _ in range(400):  # 4 s = 8 TAU
        moving.step(q, (1.0, 0.0, 0.0, 0.0), 0.01, up)
        k.append(moving.weight())
    assert (np.diff(k) >= 0.0).all()
    assert k[-1] > 0.99


def test_blend_follows_the_bridge_first_and_ends_exactly_on_the_network():
    """A bridge that is right (level), a network 40° off: the output starts near the bridge, moves to the
    network as K rises, and once K is within DONE of 1 it is the network's attitude itself."""
    bridge = _q([0.0, 0.0, 0.0])
    net = _q([math.radians(40.0), 0.0, 0.0])
    b = HoleBlend(1.0, bridge, 2.0, (0.0, 0.0, G))
    none = (1.0, 0.0, 0.0, 0.0)
    first, _ = b.step(net, none, 0.01, (0.0, 0.0, G))
    assert math.degrees(quat.inclination_error(np.array(bridge), np.array(first))) < 1.0
    t, going, out = 0.01, True, first
    while going:
        out, going = b.step(net, none, 0.01, (0.0, 0.0, G))
        t += 0.01
        assert t < 20 * TAU
    assert out == net


def test_the_bridge_is_carried_by_the_gyro():
    """K ~ 0 (a certain bridge, a network that has seen violent motion): the output's gravity direction is
    the bridge's turned by the gyro increments, whatever the network says."""
    b = HoleBlend(1.0, _q([0.0, 0.0, 0.0]), 50.0, (0.0, 0.0, G))
    step = _q([math.radians(0.5), 0.0, 0.0])  # 0.5° about x per sample
    for _ in range(20):
        out, going = b.step(_q([0.0, 1.0, 0.0]), step, 0.005, (0.0, 0.0, G))
    assert going
    truth = np.array(_q([math.radians(10.0), 0.0, 0.0]))
    assert math.degrees(quat.inclination_error(truth, np.array(out))) < 0.5


def _handover_in(qc: list, delta: list, acc: list, holes: list[Hole]) -> HandoverIn:
    """What stage 6 reads: samples (acc, 10 ms steps), the holes, the carried attitudes and increments."""
    n = len(qc)
    x = [(*a, 0.0, 0.0, 0.0) for a in acc]
    grid = GridBlock([], [], [], [], [], [], [], [], [], holes)
    return HandoverIn(Samples.of(x, [0.01] * n), grid, CarryBlock(qc, delta))


def test_handover_block_equals_samples():
    rng = np.random.default_rng(2)
    n = 400
    qc = [normalized(tuple(q)) for q in (np.array([1.0, 0, 0, 0]) + 0.2 * rng.normal(size=(n, 4))).tolist()]
    delta = [from_rotvec(*v) for v in (0.01 * rng.normal(size=(n, 3))).tolist()]
    acc = [tuple(v) for v in (np.array([0.0, 0.0, G]) + rng.normal(size=(n, 3))).tolist()]
    holes = [Hole(50, 0.3, (1.0, 0.0, 0.0), (0.0, 2.0, 0.0)), Hole(200, 0.2, (0.1, 0.0, 0.0), (0.1, 0.0, 0.0))]
    block = _handover_in(qc, delta, acc, holes)
    whole = Handover(True).run(block)
    assert block.carry.q == qc  # its input is left as it was
    one = Handover(True)
    for k in range(n):
        hk = [h._replace(sample=0) for h in holes if h.sample == k]
        part = one.run(_handover_in([qc[k]], [delta[k]], [acc[k]], hk))
        assert part.q[0] == whole.q[k] and part.blend_sd_deg[0] == whole.blend_sd_deg[k]
        assert part.bridge_sd_deg == ({0: whole.bridge_sd_deg[k]} if k in whole.bridge_sd_deg else {})
    assert whole.blend_sd_deg[50] > 0.0 and whole.q[60] != qc[60]  # the hand-over ran
    assert not any(whole.fresh_sd_deg)  # no gap


def test_after_a_gap_the_fresh_network_sigma_goes_out_until_it_is_small():
    n = 400  # 4 s at rest: σ_f = S_REST · exp(−t / TAU) falls below FRESH_DONE after 2.65 s
    qc = [(1.0, 0.0, 0.0, 0.0)] * n
    delta = [(1.0, 0.0, 0.0, 0.0)] * n
    acc = [(0.0, 0.0, G)] * n
    h = Handover(True)
    h.restart(Cause.GAP)
    out = h.run(_handover_in(qc, delta, acc, []))
    sd = np.array(out.fresh_sd_deg)
    assert sd[0] == pytest.approx(2.0, rel=1e-3) and (np.diff(sd[sd > 0]) < 0).all()
    assert sd[-1] == 0.0 and h.fresh is None
    assert out.q == qc and not any(out.blend_sd_deg)  # the attitude and the heading's weighting untouched


def test_after_a_hole_in_motion_the_output_hands_over_from_the_bridge_to_the_fresh_network():
    """The fresh network restarts from the accelerometer, which shaking tilts by tens of degrees; the gyro
    bridge is right. With the hand-over the output stays near the bridge until the network has settled;
    without it (hole_blend=false) the fresh network's error is published at once."""
    acc, gyr, dt, after, q_true = shaken_with_a_hole()
    errs = {}
    for blend in (True, False):
        est = RiannEstimator(hole_blend=blend)
        q = est.update_batch(acc, gyr, dt)
        assert est.network.holes == 1
        errs[blend] = np.degrees(quat.inclination_error(q_true, q))
    first = (after >= 0.0) & (after < 1.0)
    assert errs[True][first].max() < 5.0, errs[True][first].max()
    assert errs[False][first].max() > 10.0, errs[False][first].max()
    settled = after > 2.0  # both are the network's own output again
    assert np.abs(errs[True][settled] - errs[False][settled]).max() < 0.5


def test_after_a_hole_at_rest_the_fresh_network_takes_over_within_a_tenth_of_a_second():
    """The sensor was tilted 40° during the hole and is at rest on both sides: the bridge (no rotation) is
    wrong, and the fresh network, right at rest, takes over at once."""
    _, t, err = hole_stream(0.1)
    assert err[0] > 30.0  # the bridged sample that ends the hole
    assert err[(t >= 0.1) & (t < 3.0)].max() < 1.0


@pytest.mark.slow
def test_the_hand_over_is_the_same_per_sample_and_in_chunks():
    acc, gyr, dt, after, _ = shaken_with_a_hole(rate=100.0)
    gyr = gyr + np.random.default_rng(5).normal(0.0, 0.5, gyr.shape)  # turning too: a real blend on both paths
    est = RiannEstimator()
    qs = np.array([est.update(acc[i], gyr[i], dt[i]) for i in range(len(dt))])
    est.reset()
    cut = int(np.argmax(after >= 0.3))  # split the batch in the middle of the hand-over
    qb = np.vstack([est.update_batch(acc[:cut], gyr[:cut], dt[:cut]),
                    est.update_batch(acc[cut:], gyr[cut:], dt[cut:])])
    assert np.abs(qs - qb).max() < 1e-5
