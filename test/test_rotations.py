"""riann_ros/rotations.py: the plain-float rotations the hand-over and the heading use."""

from __future__ import annotations

import math

import numpy as np
import pytest

from riann_ros import quaternion as quat
from riann_ros.rotations import gravity, tilt_to


def _q(rotvec: list[float]) -> tuple[float, float, float, float]:
    w, x, y, z = quat.from_rotvec(rotvec).tolist()
    return w, x, y, z


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
