"""The online magnetometer calibration in front of the estimators (riann_ros.magcal.frontend, RIANN's stage 7a):
the configured calibration as a hypothesis, the heading and its σ while the calibration converges, a ground robot
turning about the vertical only, and what a reset, a gap and a new prior do."""

from __future__ import annotations

import math

import numpy as np
import pytest
from helpers_mag import ESTIMATORS, per_sample

from riann_ros import quaternion as quat
from riann_ros.datasets.synthetic import generate
from riann_ros.estimators import create
from riann_ros.gate import GateConfig
from riann_ros.magcal.frontend import FrontEndConfig, MagFrontEnd
from riann_ros.magcal.input import MagConfig, MagInput
from riann_ros.magcal.records import CALIBRATED, IDENTITY_9, UT, MagCalibration, MagCalPrior
from riann_ros.magcal.synthetic import distort, ground_robot
from riann_ros.stream import EstimatorStream

H_TRUE_UT = np.array([18.0, -12.0, 9.0])  # a robot's hard iron (µT)


def robot(turns: int = 8):
    """A ground robot (mount tilted 10°, -5°): rest, then turns and straight runs, then rest and straight again."""
    phases = [("rest", 3.0, 0.0)] + [("turn", 6.0, 30.0), ("straight", 3.0, 0.0), ("turn", 6.0, -45.0)] * turns
    phases += [("rest", 10.0, 0.0), ("straight", 10.0, 0.0)]
    rec = ground_robot(phases, rate_hz=100.0, mount_rpy_deg=(10.0, -5.0, 30.0), gyr_noise=0.003, seed=1)
    return rec, 3.0 + 15.0 * turns


def heading_error_deg(ref: np.ndarray, q: np.ndarray) -> np.ndarray:
    return np.degrees(quat.heading_error(ref, q))


def stream_of(name: str, **params) -> EstimatorStream:
    return EstimatorStream(create(name, **params), GateConfig(nominal_rate=100.0), MagConfig())


@pytest.mark.slow
@pytest.mark.parametrize("name", ESTIMATORS)
def test_a_ground_robot_turning_about_the_vertical_calibrates_and_the_heading_converges(name):
    """The hard iron's horizontal part is observed by turning about the vertical; the vertical part is not (and
    moves no heading): the heading converges, the σ covers the error meanwhile, nothing diverges, and once the
    turns stop the calibration does not move."""
    rec, t_turns = robot()
    raw = distort(rec.quat_ref, H_TRUE_UT * UT, noise_t=0.4e-6, seed=2)
    s = stream_of(name)
    t = (rec.stamps_ns - rec.stamps_ns[0]) * 1e-9
    turning = t < t_turns
    q, ok = s.process_batch(rec.stamps_ns[turning], rec.acc[turning], rec.gyr[turning], raw[turning])
    sig = np.degrees(s.batch_sigma[:, 1])
    err = heading_error_deg(rec.quat_ref[turning], q)
    status = s.mag_cal_status()
    assert status is not None and not status.prior_holds  # the 24 µT offset was found out
    assert ok[1:].all() and np.all(np.isfinite(q[ok])) and np.all(np.isfinite(sig[ok]))  # (the gate drops stamp 0)
    last = t[turning] > t_turns - 20.0
    assert np.sqrt(np.mean(err[last] ** 2)) < 4.0  # converged (without calibration: tens of degrees)
    cal = s.mag_calibration()
    assert cal is not None
    axis = quat.rotate(quat.conjugate(rec.quat_ref[0]), np.array([0.0, 0.0, 1.0]))
    h = np.asarray(cal.hard_iron_t) / UT - H_TRUE_UT
    assert np.linalg.norm(h - (h @ axis) * axis) < 1.5  # across the turning axis: found
    if name == "riann":  # the σ it reports is no confident wrong heading while it converges
        assert np.mean(np.abs(err[ok]) <= 1.96 * sig[ok]) > 0.8
    # rest and straight driving: the calibration does not move at all
    after = ~turning
    before = s.mag_calibration()
    s.process_batch(rec.stamps_ns[after], rec.acc[after], rec.gyr[after], raw[after])
    still = s.mag_calibration()
    assert still is not None and before is not None
    moved = np.abs(np.asarray(still.hard_iron_t) - np.asarray(before.hard_iron_t)).max()
    assert moved < 1e-6 * UT or still.windows <= before.windows + 1  # at most the last turn's window closing


@pytest.mark.parametrize("name", ["madgwick", "mahony", "vqf"])
def test_the_classical_filters_heading_follows_the_calibration_that_takes_over(name):
    """A wrong configured calibration (a 41 µT hard iron nobody measured): once the windows make the estimate the
    calibration the field gets, the filter's heading is set from it as at the filter's start (VQF: its magnetic part
    restarted), not left to the filter's own slow gain from where the wrong calibration took it (there it stays
    14–31° off over 10–20 s)."""
    rec = generate(duration=90.0, rate=100.0, seed=0, bias=0.0, gyr_noise=0.002)  # its first 30 s
    raw = distort(rec.quat_ref, np.array([30.0, 20.0, -20.0]) * UT, noise_t=0.4e-6, seed=2)
    est = create(name)
    front = MagFrontEnd(FrontEndConfig.of(est.params))  # (the stream's, without the gate)
    est.take_front_end(front)
    q = np.vstack([est.update_batch(rec.acc[i:i + 100], rec.gyr[i:i + 100], rec.dt[i:i + 100], raw[i:i + 100])
                   for i in range(0, 3000, 100)])
    assert front.cal is not None and front.cal.changes.count > 0
    err = heading_error_deg(rec.quat_ref[:3000], q)
    after = (rec.t[:3000] >= 10.0) & (rec.t[:3000] < 20.0)
    assert np.sqrt(np.mean(err[after] ** 2)) < 8.0


@pytest.mark.parametrize("name", ESTIMATORS)
def test_a_right_configured_calibration_is_used_as_it_is(name):
    """The configured calibration right (the readings distorted by exactly it): the gyro-aided test keeps it, and
    the outputs equal those with the online calibration off (the field calibrated by the stream)."""
    rec, _ = robot(turns=2)
    h = tuple(float(v) for v in H_TRUE_UT * UT)
    raw = distort(rec.quat_ref, H_TRUE_UT * UT, noise_t=0.4e-6, seed=2)
    out = []
    for on in (True, False):
        s = EstimatorStream(create(name, mag_calibration=on), GateConfig(nominal_rate=100.0),
                            MagConfig(mag_hard_iron=h))
        out.append(s.process_batch(rec.stamps_ns, rec.acc, rec.gyr, raw)[0])
        status = s.mag_cal_status()  # (off: the gyro-aided test runs as a monitor)
        assert status is not None and status.prior_holds and status.windows > 5
    np.testing.assert_allclose(out[0], out[1], atol=1e-6)


def test_the_heading_sigma_says_the_configured_calibration_is_not_yet_tested():
    """At rest nothing tests the configured calibration: the heading uses it, and its σ says it is unverified; the
    first turns that agree with it bring the σ down to a calibrated field's (once the doubt of the field's timing,
    which turns too slow for the lag scan leave, has decayed: magcal/lag.py)."""
    rec, _ = robot(turns=2)
    raw = distort(rec.quat_ref, np.zeros(3), noise_t=0.4e-6, seed=2)
    s = stream_of("riann")
    s.process_batch(rec.stamps_ns, rec.acc, rec.gyr, raw)
    sig = np.degrees(s.batch_sigma[:, 1])
    t = (rec.stamps_ns - rec.stamps_ns[0]) * 1e-9
    assert np.all(sig[(t > 1.0) & (t < 3.0)] > 20.0)  # the initial rest: unverified
    assert np.all(sig[t > t[-1] - 5.0] < 3.5)  # verified: the field heading's own σ (2.5°) and the tilt's share
    assert s.mag_cal_status().prior_holds


@pytest.mark.parametrize("name", ESTIMATORS)
def test_the_calibration_belongs_to_the_robot(name):
    """A reset and a gap keep the calibration (its open window is dropped); a new prior starts it anew."""
    rec, _ = robot(turns=2)
    raw = distort(rec.quat_ref, H_TRUE_UT * UT, noise_t=0.4e-6, seed=2)
    s = stream_of(name)
    s.process_batch(rec.stamps_ns, rec.acc, rec.gyr, raw)
    before = s.mag_calibration()
    assert before is not None and before.windows > 5
    s.reset()
    s.estimator.on_gap()
    assert s.mag_calibration() == before
    s.configure_mag(MagConfig())  # the same prior: kept
    assert s.mag_calibration() == before
    s.configure_mag(MagConfig(mag_hard_iron=(1e-6, 0.0, 0.0)))  # a new one: anew
    assert s.mag_calibration().windows == 0
    saved = MagCalPrior.from_calibration(before)  # a saved calibration as the prior
    s.configure_mag(MagConfig(), saved)
    assert s.mag_calibration().hard_iron_t == pytest.approx(before.hard_iron_t, abs=1e-12)


def test_with_calibration_on_the_stream_passes_the_raw_field():
    h = (10e-6, 20e-6, -40e-6)
    cfg = MagConfig(mag_hard_iron=h)
    raw = np.array([30e-6, 20e-6, -40e-6])  # calibrated: (20, 0, 0) µT
    assert MagInput(cfg, raw=True).prepare(raw) == pytest.approx(tuple(raw))
    assert MagInput(cfg).prepare(raw) == pytest.approx((20e-6, 0.0, 0.0))
    # (off, the front end calibrates with the configured values itself: its gyro-aided test runs as a monitor)
    assert stream_of("vqf").mag.raw and stream_of("vqf", mag_calibration=False).mag.raw


@pytest.mark.parametrize("name", ESTIMATORS)
def test_batch_and_per_sample_give_the_same_numbers_with_calibration(name):
    rec, _ = robot(turns=1)
    raw = distort(rec.quat_ref, H_TRUE_UT * UT, noise_t=0.4e-6, seed=2)
    n = 1500
    a, b = stream_of(name), stream_of(name)
    qa, _ = a.process_batch(rec.stamps_ns[:n], rec.acc[:n], rec.gyr[:n], raw[:n])
    qb, _ = per_sample(b, rec.stamps_ns[:n], rec.acc[:n], rec.gyr[:n], raw[:n])
    np.testing.assert_allclose(qa, qb, atol=1e-5 if name == "riann" else 1e-9)
    np.testing.assert_allclose(a.batch_sigma[-1], b.sigma, atol=1e-6)
    assert a.front is not None and a.front.cal is not None
    assert a.front.cal.changes.count > 0  # the estimate took over (a filter's heading checked there)
    assert a.mag_calibration() == b.mag_calibration() or math.isclose(
        a.mag_calibration().hard_iron_t[0], b.mag_calibration().hard_iron_t[0], abs_tol=1e-9)


def test_state_calibrated_once_converged():
    rec, _ = robot(turns=10)
    raw = distort(rec.quat_ref, H_TRUE_UT * UT, noise_t=0.4e-6, seed=2)
    s = stream_of("madgwick")
    s.process_batch(rec.stamps_ns, rec.acc, rec.gyr, raw)
    st = s.mag_cal_status()
    assert st.state == CALIBRATED and st.converged_after_s is not None and 3.0 < st.converged_after_s < 150.0


def test_the_classical_filters_calibration_tilt_is_not_tilted_by_a_linear_acceleration():
    """The calibration in front of Madgwick, Mahony and VQF needs the sensor's tilt (for the tolerance of its test and
    the heading σ): the gyro carries it and the accelerometer pulls it toward gravity over seconds, so half a second
    of 5 m/s² sideways (a robot braking; the accelerometer alone reads 27° of tilt) moves it by a few degrees."""
    front = MagFrontEnd()
    n = 400
    acc = np.tile([0.0, 0.0, 9.81], (n, 1))
    acc[200:250, 0] = 5.0  # 0.5 s of acceleration along x, no rotation
    worst = 0.0
    for i in range(n):
        front.rows([acc[i].tolist()], [[0.0, 0.0, 0.0]], [0.01], [(0.0, 2e-5, -4e-5)])
        up = quat.rotate(np.asarray(front.tilt.q)[None], np.array([[0.0, 0.0, 1.0]]))[0]
        worst = max(worst, math.degrees(math.acos(min(1.0, up[2]))))
    assert 1.0 < worst < 6.0


@pytest.mark.parametrize("name", ESTIMATORS)
@pytest.mark.parametrize("calibrate", [True, False])
def test_a_saved_calibration_20_ut_off_is_covered_from_the_first_second(name, calibrate):
    """A calibration saved on another run, 20 µT off the hard iron there now (its covariance says ±0.5 µT): until the
    windows have tested it the heading's σ is the doubt an untested calibration carries, so it covers the error from
    the first second, at rest and while the first turns test it; with mag_calibration off (the test as a monitor)
    too."""
    rec, _ = robot(turns=3)
    raw = distort(rec.quat_ref, H_TRUE_UT * UT, noise_t=0.4e-6, seed=2)
    wrong = tuple(float(v) for v in (H_TRUE_UT + np.array([20.0, 0.0, 0.0])) * UT)
    saved = MagCalibration(hard_iron_t=wrong, soft_iron=IDENTITY_9,  # type: ignore[arg-type]
                           covariance=tuple(float(v) for v in np.diag([1e-6] * 9 + [(0.5 * UT) ** 2] * 3).ravel()),
                           state=CALIBRATED, windows=200, converged_after_s=30.0, soft_iron_model="full")
    s = EstimatorStream(create(name, mag_calibration=calibrate), GateConfig(nominal_rate=100.0), MagConfig(),
                        MagCalPrior.from_calibration(saved))
    q, ok = s.process_batch(rec.stamps_ns, rec.acc, rec.gyr, raw)
    err = heading_error_deg(rec.quat_ref, q)
    sig = np.degrees(s.batch_sigma[:, 1])
    t = (rec.stamps_ns - rec.stamps_ns[0]) * 1e-9
    first = ok & (t >= 1.0) & (t < 20.0)
    assert np.abs(err[first]).max() > 10.0  # the file is wrong enough to matter
    assert np.mean(np.abs(err[first]) <= 1.96 * sig[first]) >= 0.9


@pytest.mark.parametrize("name", ["riann", "vqf"])
def test_a_saved_calibration_from_another_run_is_covered_while_the_hard_iron_moved(name):
    """A file saved on another run of the same sensor, whose fit says ±0.5 µT, while the hard iron has moved by 2 µT
    since (as much as it moves between two BROAD runs, bench/mag_run_to_run.py): the file's doubt is widened by the
    run-to-run figure at load, so the heading's σ covers the error over the whole run and in every stretch of it."""
    rec, _ = robot(turns=6)
    raw = distort(rec.quat_ref, H_TRUE_UT * UT, noise_t=0.4e-6, seed=3)
    moved = tuple(float(v) for v in (H_TRUE_UT + np.array([1.2, -1.0, 1.2])) * UT)  # |2.0| µT
    saved = MagCalibration(hard_iron_t=moved, soft_iron=IDENTITY_9,  # type: ignore[arg-type]
                           covariance=tuple(float(v) for v in np.diag([1e-6] * 9 + [(0.5 * UT) ** 2] * 3).ravel()),
                           state=CALIBRATED, windows=200, converged_after_s=30.0, soft_iron_model="full")
    prior = MagCalPrior.from_calibration(saved)
    assert np.sqrt(np.diag(np.reshape(prior.covariance, (12, 12)))[9:]).min() > 1.2 * UT
    s = EstimatorStream(create(name), GateConfig(nominal_rate=100.0), MagConfig(), prior)
    q, ok = s.process_batch(rec.stamps_ns, rec.acc, rec.gyr, raw)
    err = np.abs(heading_error_deg(rec.quat_ref, q))
    sig = np.degrees(s.batch_sigma[:, 1])
    t = (rec.stamps_ns - rec.stamps_ns[0]) * 1e-9
    inside = ok & (t >= 1.0)
    assert np.mean(err[inside] <= 1.96 * sig[inside]) >= 0.9
    for start in np.arange(1.0, t[-1] - 10.0, 10.0):  # every 10 s stretch
        part = inside & (t >= start) & (t < start + 10.0)
        assert np.mean(err[part] <= 1.96 * sig[part]) >= 0.8, start
