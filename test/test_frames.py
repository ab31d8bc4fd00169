"""World-frame conventions and roll/pitch/yaw (riann_ros.frames, ROS-free)."""

from __future__ import annotations

import numpy as np
import pytest

from riann_ros import frames
from riann_ros import quaternion as quat

H = np.sqrt(0.5)
RNG = np.random.default_rng(12)


def random_quats(n: int) -> np.ndarray:
    q = quat.normalize(RNG.normal(size=(n, 4)))
    return q * np.sign(q[:, :1])


def matrix(q) -> np.ndarray:
    """Rotation matrix of a quaternion, from its action on the basis vectors."""
    return np.stack([quat.rotate(q, e) for e in np.eye(3)], axis=-1)


@pytest.mark.parametrize("frame", frames.WORLD_FRAMES)
def test_quaternion_is_the_written_axis_change(frame: str) -> None:
    c = frames.FROM_ENU[frame]
    np.testing.assert_allclose(matrix(c), frames.FROM_ENU_MATRIX[frame], atol=1e-15)
    assert np.linalg.det(frames.FROM_ENU_MATRIX[frame]) == pytest.approx(1.0)  # a rotation, not a reflection


def test_axis_changes_are_the_physical_ones() -> None:
    v = np.array([1.0, 2.0, 3.0])  # east 1, north 2, up 3
    east, north, up = v
    np.testing.assert_allclose(quat.rotate(frames.FROM_ENU["ned"], v), [north, east, -up], atol=1e-15)
    np.testing.assert_allclose(quat.rotate(frames.FROM_ENU["nwu"], v), [north, -east, up], atol=1e-15)
    np.testing.assert_allclose(quat.rotate(frames.FROM_ENU["enu"], v), v)


@pytest.mark.parametrize("frame", frames.WORLD_FRAMES)
def test_to_world_maps_world_vectors_and_keeps_sensor_vectors(frame: str) -> None:
    """q_W rotates a sensor vector to C_W applied to where q_ENU puts it: the same physical direction."""
    q = random_quats(50)
    qw = frames.to_world(q, frame)
    v = RNG.normal(size=(50, 3))
    np.testing.assert_allclose(quat.rotate(qw, v), (frames.FROM_ENU_MATRIX[frame] @ quat.rotate(q, v).T).T,
                               atol=1e-12)
    np.testing.assert_allclose(np.linalg.norm(qw, axis=1), 1.0, atol=1e-12)


@pytest.mark.parametrize("frame", frames.WORLD_FRAMES)
def test_scalar_and_vector_paths_agree(frame: str) -> None:
    q = random_quats(20)
    vec = frames.to_world(q, frame)
    sca = np.array([frames.to_world_scalar(*map(float, row), frame) for row in q])
    np.testing.assert_allclose(sca, vec, atol=1e-15)
    np.testing.assert_allclose(np.array([frames.rpy_deg_scalar(*row) for row in vec]), frames.rpy_deg(vec),
                               atol=1e-9)


def test_level_sensor_at_heading_zero_in_each_frame() -> None:
    """What a level, z-up sensor at a 6D heading of 0 (identity in ENU) reads in each frame."""
    ident = quat.IDENTITY
    np.testing.assert_allclose(frames.to_world(ident, "enu"), [1.0, 0.0, 0.0, 0.0])
    np.testing.assert_allclose(frames.to_world(ident, "ned"), [0.0, H, H, 0.0], atol=1e-15)
    np.testing.assert_allclose(frames.to_world(ident, "nwu"), [H, 0.0, 0.0, -H], atol=1e-15)
    np.testing.assert_allclose(frames.rpy_deg(frames.to_world(ident, "enu")), [0.0, 0.0, 0.0], atol=1e-12)
    np.testing.assert_allclose(np.abs(frames.rpy_deg(frames.to_world(ident, "ned"))), [180.0, 0.0, 90.0],
                               atol=1e-9)
    np.testing.assert_allclose(frames.rpy_deg(frames.to_world(ident, "nwu")), [0.0, 0.0, -90.0], atol=1e-12)


def test_heading_relation_between_frames() -> None:
    """Level sensor at ENU yaw ψ: NED yaw 90° − ψ, NWU yaw ψ − 90° (the documented 6D heading meaning)."""
    for psi in (-170.0, -30.0, 0.0, 45.0, 120.0):
        q = frames.from_rpy_deg(0.0, 0.0, psi)
        assert frames.rpy_deg(q)[2] == pytest.approx(psi)
        ned = frames.rpy_deg(frames.to_world(q, "ned"))
        nwu = frames.rpy_deg(frames.to_world(q, "nwu"))
        assert (ned[2] - (90.0 - psi) + 180.0) % 360.0 - 180.0 == pytest.approx(0.0, abs=1e-9)
        assert (nwu[2] - (psi - 90.0) + 180.0) % 360.0 - 180.0 == pytest.approx(0.0, abs=1e-9)
        assert nwu[:2] == pytest.approx([0.0, 0.0], abs=1e-9)


def test_tilt_reads_the_same_in_enu_and_nwu_and_mirrored_in_ned() -> None:
    """A z-up world frame keeps roll and pitch; for an FRD-like sensor (z down) NED reads the ENU tilt."""
    q = frames.from_rpy_deg(10.0, -20.0, 0.0)
    assert frames.rpy_deg(frames.to_world(q, "nwu"))[:2] == pytest.approx([10.0, -20.0])
    # a sensor mounted upside down (z down, x forward, y right) tilted: level in NED is roll 0
    frd = quat.from_rotvec([np.pi, 0.0, 0.0])
    assert frames.rpy_deg(frames.to_world(frd, "ned"))[:2] == pytest.approx([0.0, 0.0], abs=1e-9)


def test_rpy_round_trip_and_conventions() -> None:
    for roll, pitch, yaw in [(10.0, 20.0, 30.0), (-170.0, 80.0, -100.0), (0.0, -89.0, 179.0)]:
        q = frames.from_rpy_deg(roll, pitch, yaw)
        np.testing.assert_allclose(frames.rpy_deg(q), [roll, pitch, yaw], atol=1e-7)
    # ZYX: yaw first about world z, then pitch about the new y, then roll about the newest x
    q = frames.from_rpy_deg(0.0, 0.0, 90.0)
    np.testing.assert_allclose(quat.rotate(q, [1.0, 0.0, 0.0]), [0.0, 1.0, 0.0], atol=1e-15)
    q = frames.from_rpy_deg(0.0, 30.0, 0.0)  # positive pitch: nose (x) down in a z-up frame
    assert quat.rotate(q, [1.0, 0.0, 0.0])[2] < 0.0
    # gimbal lock stays finite
    assert np.isfinite(frames.rpy_deg(frames.from_rpy_deg(0.0, 90.0, 0.0))).all()


def test_unknown_world_frame_is_refused() -> None:
    with pytest.raises(ValueError, match="world_frame must be one of enu, ned, nwu"):
        frames.to_world(quat.IDENTITY, "xyz")
