"""riann_ros/estimators/riann/s4a_ensemble.py: the copies' frames and rows, and their combination (the plain-float
form against the vectorised reference)."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from riann_ros import quaternion as quat
from riann_ros.estimators.riann.s4a_ensemble import (
    MAX_COPIES,
    combine,
    combine_floats,
    copy_rows,
    frames,
    gravity_rows,
    rotate_rows,
)


def _quat_of(r: np.ndarray) -> np.ndarray:
    """Unit quaternion (w, x, y, z) of a proper rotation matrix."""
    from scipy.spatial.transform import Rotation

    x, y, z, w = Rotation.from_matrix(r).as_quat()
    return np.array([w, x, y, z])


def test_frames_are_rotations_as_far_apart_as_possible():
    rs = frames(MAX_COPIES)
    assert len(rs) == 4 and np.array_equal(rs[0], np.eye(3))
    for r in rs:
        assert np.allclose(r @ r.T, np.eye(3), atol=1e-12) and np.isclose(np.linalg.det(r), 1.0)
    for i in range(4):
        for j in range(i + 1, 4):
            # trace(RiᵀRj) = 1 + 2 cos(angle): -1 is 180°, the largest angle between two rotations
            assert np.isclose(np.trace(rs[i].T @ rs[j]), -1.0, atol=1e-12)
    for r in rs[1:]:  # no turn axis near a sensor axis: at least 30° from each
        axis = np.linalg.eigh(r)[1][:, -1]
        assert np.abs(axis).max() < np.cos(np.radians(30.0))
    assert len(frames(1)) == 1
    with pytest.raises(ValueError):
        frames(0)
    with pytest.raises(ValueError):
        frames(MAX_COPIES + 1)


def test_rotate_rows_turns_acc_and_gyr_and_keeps_dt():
    rows = np.array([[1.0, 2.0, 3.0, 0.1, 0.2, 0.3, 0.005]])
    r = frames(2)[1]
    out = rotate_rows(rows, r)
    assert np.allclose(out[0, :3], r @ rows[0, :3]) and np.allclose(out[0, 3:6], r @ rows[0, 3:6])
    assert out[0, 6] == 0.005 and rows[0, 0] == 1.0  # input untouched


def test_combine_maps_each_copy_back_and_averages_the_gravity_directions():
    rng = np.random.default_rng(3)
    rs = frames(4)
    q_true = quat.normalize(rng.normal(size=(50, 4)))
    # copy m saw the sensor frame turned by R_m: its exact attitude is q_true ⊗ r_m⁻¹
    exact = [quat.multiply(q_true, quat.conjugate(_quat_of(r))) for r in rs]
    q, spread = combine(exact, rs)
    assert np.abs(spread).max() < 1e-6  # exact copies agree
    assert np.allclose(gravity_rows(q), gravity_rows(q_true), atol=1e-9)
    # the heading is copy 0's: q differs from it by a turn about a horizontal axis only
    d = quat.multiply(quat.conjugate(exact[0]), q)  # sensor-frame turn
    axis_world = quat.rotate(exact[0], d[:, 1:])
    assert np.abs(axis_world[:, 2]).max() < 1e-9
    # errors: copies tilted by +e, -e, +e, -e about the same world axis average out
    e = 0.05
    tilts = [quat.from_rotvec([s * e, 0.0, 0.0]) for s in (1, -1, 1, -1)]
    noisy = [quat.multiply(quat.multiply(t, q_true), quat.conjugate(_quat_of(r)))
             for t, r in zip(tilts, rs, strict=True)]
    err_one = np.degrees(quat.inclination_error(q_true, noisy[0]))
    q_all, spread = combine(noisy, rs)
    err_all = np.degrees(quat.inclination_error(q_true, q_all))
    assert np.allclose(err_one, np.degrees(e), atol=1e-6) and err_all.max() < 1e-6
    assert np.allclose(spread, e, rtol=1e-3)  # the copies' angles from their mean direction: e each
    one, none = combine(exact[:1], rs[:1])
    assert one is exact[0] and not none.any()


@settings(max_examples=100, deadline=None)
@given(seed=st.integers(0, 2**32 - 1), copies=st.integers(2, MAX_COPIES), rows=st.integers(1, 4),
       scale=st.floats(0.5, 2.0))
def test_combine_in_floats_equals_the_vectorised_reference(seed, copies, rows, scale):
    """The node's path (a few rows, plain floats, each copy's output normalised first) gives what the reference
    gives on the normalised outputs, attitude and spread, on random copies' outputs of any scale."""
    rng = np.random.default_rng(seed)
    rs = frames(copies)
    outs = [scale * rng.normal(size=(rows, 4)) for _ in rs]
    q, spread = combine_floats(outs, rs)
    ref_q, ref_spread = combine([o / np.linalg.norm(o, axis=1, keepdims=True) for o in outs], rs)
    assert np.abs(q - ref_q).max() < 1e-12 and np.abs(spread - ref_spread).max() < 1e-12


def test_copy_rows_equals_rotate_rows_per_copy():

    rng = np.random.default_rng(4)
    rows = np.column_stack([rng.normal(0, 3, (500, 6)), np.full(500, 0.005)])
    rots = frames(MAX_COPIES)
    got = copy_rows(rots)(rows)
    for m, r in enumerate(rots):
        want = (rows if m == 0 else rotate_rows(rows, r)).astype(np.float32)
        assert np.abs(got[m].astype(np.float64) - want).max() <= 1e-6 * np.abs(want).max()
