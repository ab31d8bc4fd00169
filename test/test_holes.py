"""The hand-over from the gyro bridge to the fresh network after a hole (riann_ros.estimators.holes)."""

from __future__ import annotations

import math

import numpy as np
import pytest

from riann_ros import quaternion as quat
from riann_ros.estimators.riann.s6_handover import TAU, HoleBlend, bridge_sigma
from riann_ros.rotations import gravity, tilt_to

G = 9.81


def _q(rotvec: list[float]) -> tuple[float, float, float, float]:
    return tuple(quat.from_rotvec(rotvec).tolist())  # type: ignore[return-value]


def _yaw(q) -> float:
    w, x, y, z = q
    return math.atan2(2 * (w * z + x * y), 1 - 2 * (y * y + z * z))


def test_gravity_is_world_up_in_the_sensor_frame():
    q = _q([0.3, -0.5, 1.2])
    expect = quat.rotate(quat.conjugate(np.array(q)), [0.0, 0.0, 1.0])
    assert np.allclose(gravity(q), expect, atol=1e-12)


@pytest.mark.parametrize("target", [[0.0, 0.0, 1.0], [0.3, -0.2, 0.9], [0.0, -1.0, 0.1], [0.5, 0.5, -0.7]])
def test_tilt_to_gives_the_gravity_direction_and_keeps_the_heading(target):
    q = _q([0.4, 0.2, 2.0])
    v = np.array(target) / np.linalg.norm(target)
    out = tilt_to(q, tuple(v))
    assert np.allclose(gravity(out), v, atol=1e-9)
    assert abs(math.sqrt(sum(c * c for c in out)) - 1.0) < 1e-12
    # the correction is about a horizontal world axis: its rotation has no vertical component
    corr = quat.multiply(np.array(out), quat.conjugate(np.array(q)))
    assert abs(corr[3]) < 1e-9


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
