"""The virtual-rotation ensemble (riann_ros/estimators/riann/s4a_ensemble.py): its frames, its combination, and the
estimator's output against the four copies of the network run directly."""

from __future__ import annotations

import numpy as np
import onnxruntime as ort
import pytest

from conftest import gate_dts, rmse
from riann_ros import quaternion as quat
from riann_ros.estimators import create
from riann_ros.estimators.riann import default_model_path
from riann_ros.estimators.riann.s4a_ensemble import FLOAT_ROWS, MAX_COPIES, combine, frames, gravity_rows, rotate_rows


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
    q = combine(exact, rs)
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
    err_all = np.degrees(quat.inclination_error(q_true, combine(noisy, rs)))
    assert np.allclose(err_one, np.degrees(e), atol=1e-6) and err_all.max() < 1e-6
    assert combine(exact[:1], rs[:1]) is exact[0]


def test_combine_per_row_in_floats_equals_the_vectorised_combination():
    """The node's path (a few rows, plain floats, normalising) gives what the batch path gives."""
    rng = np.random.default_rng(5)
    rs = frames(4)
    outs = [quat.normalize(rng.normal(size=(40, 4))) for _ in rs]
    whole = combine(outs, rs)  # 40 rows: vectorised
    assert len(whole) > FLOAT_ROWS
    for i in range(0, 40, FLOAT_ROWS):
        part = combine([1.001 * o[i : i + FLOAT_ROWS] for o in outs], rs)  # not quite unit: normalised
        assert np.abs(part - whole[i : i + FLOAT_ROWS]).max() < 1e-12


@pytest.mark.slow
def test_estimator_output_is_the_four_network_copies_combined(broad_trial):
    """At 285.7 Hz the grid rows are the samples: without the bias front end the output's inclination is the
    combination of the official network run directly on the four turned copies of the IMU."""
    rec = broad_trial("07").slice(0, 6000)
    sess = ort.InferenceSession(str(default_model_path()))
    rows = np.column_stack([rec.acc, rec.gyr, gate_dts(rec)])
    outs = []
    for r in frames(4):
        x = rotate_rows(rows, r).astype(np.float32)[None]
        out, _ = sess.run(None, {"input": x, "h0": np.zeros((2, 1, 1, 200), np.float32)})
        outs.append(out[0] / np.linalg.norm(out[0], axis=1, keepdims=True))
    ref = combine(outs, frames(4))
    est = create("riann", gyro_bias_estimation=False)
    q = est.update_batch(rec.acc, rec.gyr, gate_dts(rec))
    assert np.degrees(quat.inclination_error(ref, q)).max() < 1e-3
    # the copies disagree (else there would be nothing to average): copy 0 alone is not the ensemble
    assert np.degrees(quat.inclination_error(outs[0], ref)).max() > 0.1


@pytest.mark.slow
def test_ensemble_is_more_accurate_than_one_network_on_broad(broad_trial):
    """Measured on trial 07 (fast rotation): 0.93° with four copies, 1.47° with one."""
    rec = broad_trial("07")
    one = rmse(rec, create("riann", ensemble=1).update_batch(rec.acc, rec.gyr, gate_dts(rec)))
    four = rmse(rec, create("riann").update_batch(rec.acc, rec.gyr, gate_dts(rec)))
    assert four < 0.8 * one, (four, one)


def test_copy_rows_equals_rotate_rows_per_copy():
    from riann_ros.estimators.riann.s4a_ensemble import copy_rows

    rng = np.random.default_rng(4)
    rows = np.column_stack([rng.normal(0, 3, (500, 6)), np.full(500, 0.005)])
    rots = frames(MAX_COPIES)
    got = copy_rows(rots)(rows)
    for m, r in enumerate(rots):
        want = (rows if m == 0 else rotate_rows(rows, r)).astype(np.float32)
        assert np.abs(got[m].astype(np.float64) - want).max() <= 1e-6 * np.abs(want).max()
