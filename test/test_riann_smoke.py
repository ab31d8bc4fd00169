"""RIANN end to end: level and tilted rest, and on the BROAD trials its accuracy at native and other rates, the
ensemble against one network, a slow stream of interval means against VQF."""

from __future__ import annotations

import numpy as np
import pytest

from conftest import gate_dts, rmse
from riann_ros import quaternion as quat
from riann_ros.constants import GRAVITY
from riann_ros.estimators import create
from riann_ros.resample import resample_recording


def test_rest_gives_level_attitude_and_unit_quaternions():
    est = create("riann")
    n = 400
    acc = np.tile([0.0, 0.0, GRAVITY], (n, 1))
    q = est.update_batch(acc, np.zeros((n, 3)), np.full(n, 0.005))
    assert np.allclose(np.linalg.norm(q, axis=1), 1.0, atol=1e-9)
    err = np.degrees(quat.inclination_error(quat.IDENTITY, q[-1]))
    assert err < 1.0


def test_tilted_rest_is_recognised():
    est = create("riann")
    q_true = quat.from_rotvec([np.radians(30.0), 0.0, 0.0])
    acc = quat.rotate(quat.conjugate(q_true), [0.0, 0.0, GRAVITY])  # gravity reaction in the sensor frame
    n = 600
    q = est.update_batch(np.tile(acc, (n, 1)), np.zeros((n, 3)), np.full(n, 0.005))
    assert np.degrees(quat.inclination_error(q_true, q[-1])) < 2.0


@pytest.mark.slow
def test_inclination_rmse_on_all_broad_trials(broad_dir, broad_trial):
    from riann_ros.datasets.broad import broad_files

    est = create("riann")
    rmses = {}
    for f in broad_files(broad_dir):
        rec = broad_trial(f.name[:2])
        est.reset()
        rmses[f.name] = rmse(rec, est.update_batch(rec.acc, rec.gyr, gate_dts(rec)))
    assert all(0.2 < v < 3.0 for v in rmses.values()), rmses
    if len(rmses) == 12:  # the 12-trial subset: measured mean 0.72 deg (0.96 with ensemble=1)
        assert 0.5 <= np.mean(list(rmses.values())) <= 0.9, rmses


@pytest.mark.slow
@pytest.mark.parametrize("trial", ["02", "07", "15"])
def test_rates_outside_the_trained_range_stay_accurate(broad_trial, trial):
    rec = broad_trial(trial)
    native = rmse(rec, create("riann").update_batch(rec.acc, rec.gyr, gate_dts(rec)))
    fast = resample_recording(rec, 1000.0)
    slow = resample_recording(rec, 25.0)
    e_fast = rmse(fast, create("riann").update_batch(fast.acc, fast.gyr, gate_dts(fast)))
    # the FFT-resampled stream is point samples: told so (the default reads a 25 Hz stream a quarter step early)
    e_slow = rmse(slow, create("riann", input_model="points").update_batch(slow.acc, slow.gyr, gate_dts(slow)))
    assert e_fast <= 1.3 * native, (native, e_fast)
    assert e_slow <= 2.5 * native, (native, e_slow)
    # and the adaptation is what makes the difference: fed straight in, 1000 Hz is far worse
    raw = create("riann", rate_adaptation=False)
    e_raw = rmse(fast, raw.update_batch(fast.acc, fast.gyr, gate_dts(fast)))
    assert e_raw > 3 * native


@pytest.mark.slow
def test_a_low_rate_stream_of_interval_means_does_not_lose_to_vqf(broad_trial):
    """BROAD 21 (fast combined motion) as a regular 25 Hz stream of interval means stamped at the end of their
    interval (``rate:25``): read at the stamps (``sample_delay=0``) RIANN lags by half a step and loses to VQF
    (measured 8.04° vs 7.16°); at its default sample delay it does not (4.65°)."""
    from riann_ros.evaluation.perturb import parse_perturbation

    rec = parse_perturbation("rate:25").start(np.random.default_rng(0))(broad_trial("21"))
    dts = gate_dts(rec)
    e = {spec: rmse(rec, create(name, **kw).update_batch(rec.acc, rec.gyr, dts))
         for spec, name, kw in (("default", "riann", {}), ("at stamps", "riann", {"sample_delay": 0.0}),
                                ("vqf", "vqf", {}))}
    assert e["default"] <= e["vqf"], e
    assert e["default"] < 0.8 * e["at stamps"], e


@pytest.mark.slow
def test_ensemble_is_more_accurate_than_one_network_on_broad(broad_trial):
    """Measured on trial 07 (fast rotation): 0.93° with four copies, 1.47° with one."""
    rec = broad_trial("07")
    one = rmse(rec, create("riann", ensemble=1).update_batch(rec.acc, rec.gyr, gate_dts(rec)))
    four = rmse(rec, create("riann").update_batch(rec.acc, rec.gyr, gate_dts(rec)))
    assert four < 0.8 * one, (four, one)
