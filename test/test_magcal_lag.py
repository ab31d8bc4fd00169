"""The magnetometer's lag scanned over 0 … mag_timeout (riann_ros.magcal.lag): a field 100 or 300 ms late is found and
rotated back over its lag for every estimator (the heading right again), a lag within the scan's resolution changes
nothing, the heading σ carries the field's timing until the scan has resolved it, and the lag monitor says so."""

from __future__ import annotations

import numpy as np
import pytest
from helpers_mag import delayed_field, field_of, moving

from riann_ros import quaternion as quat
from riann_ros.estimators import create
from riann_ros.magcal.lag import LagScan
from riann_ros.magcal.online import OnlineMagCalibrator
from riann_ros.magcal.records import MagCalPrior
from riann_ros.monitors import Level
from riann_ros.rotations import from_rotvec
from riann_ros.stream import EstimatorStream, GateConfig


def _run(name: str, delay_ms: int, seconds: float = 40.0):
    rec = moving(duration=seconds, seed=3)
    k = round(delay_ms * 1e-3 * rec.rate_hz)
    mag = delayed_field(rec, k) if k else field_of(rec.quat_ref, 0.2e-6, seed=5)
    s = EstimatorStream(create(name), GateConfig(nominal_rate=rec.rate_hz))
    q, _ = s.process_batch(rec.stamps_ns, rec.acc, rec.gyr, mag)
    t = (rec.stamps_ns - rec.stamps_ns[0]) * 1e-9
    err = np.degrees(np.abs(quat.heading_error(rec.quat_ref, q)))
    return s, float(np.sqrt(np.nanmean(err[t > 20.0] ** 2)))


@pytest.mark.parametrize("name", ["vqf", "madgwick"])
def test_a_field_300_ms_late_is_found_and_compensated(name):
    s, rms = _run(name, 300)
    assert s.front is not None and s.front.late_s == pytest.approx(0.3, abs=0.015)
    assert rms < 2.0  # (without the scan: 24–25°)
    lag = next(v for v in s.monitors.verdicts() if v.name == "magnetometer lag")
    assert lag.level == Level.WARN and "300 ms" in lag.message


@pytest.mark.parametrize("name", ["riann", "vqf"])
def test_a_field_100_ms_late_is_compensated_exactly(name):
    """100 ms is inside the latency fit's range, but the fit is first order: the scan's exact compensation takes it."""
    s, rms = _run(name, 100)
    assert s.front is not None and s.front.late_s == pytest.approx(0.1, abs=0.015)
    assert rms < 3.0


def test_until_the_lag_is_resolved_the_heading_sigma_carries_the_field_timing():
    """A field 300 ms late, from the first reading: before the scan has its windows the heading learns from a field of
    the wrong instant, and the σ it reports covers that error (the doubt decays once the lag is resolved)."""
    rec = moving(duration=40.0, seed=3)
    mag = delayed_field(rec, round(0.3 * rec.rate_hz))
    s = EstimatorStream(create("vqf"), GateConfig(nominal_rate=rec.rate_hz))
    q, ok = s.process_batch(rec.stamps_ns, rec.acc, rec.gyr, mag)
    err = np.degrees(np.abs(quat.heading_error(rec.quat_ref, q)))
    sig = np.degrees(s.batch_sigma[:, 1])
    assert s.front is not None and s.front.lag.doubt_sd < 0.1  # resolved, and decayed by the end
    wrong = ok & (err > 5.0)  # where the field's wrong instant mattered
    assert wrong.sum() > 50
    assert np.mean(err[wrong] <= 1.96 * sig[wrong]) >= 0.9  # there σ says so


def test_a_lag_within_the_scan_s_resolution_changes_nothing():
    s, _ = _run("vqf", 30, seconds=30.0)
    assert s.front is not None and s.front.late_s is None
    assert s.front.lag.lag_s == pytest.approx(0.03, abs=0.015)


def test_the_scan_needs_rotation():
    """At rest (no window turns 10°) the scan says nothing, whatever the field does."""
    scan = LagScan(0.5)
    rng = np.random.default_rng(0)
    for _ in range(3000):
        scan.add((1.0, 0.0, 0.0, 0.0), 0.01, tuple(rng.normal(0.0, 1e-6, 3) + np.array([20e-6, 0.0, -40e-6])))
    assert scan.windows == 0.0 and scan.lag_s is None and scan.late_s is None


@pytest.mark.parametrize("name", ["vqf", "madgwick", "riann"])
def test_a_late_field_gives_the_same_outputs_in_one_batch_as_in_chunks(name):
    """When the scan finds the lag the calibration starts anew mid-batch: every later row reads the new calibrator,
    so one batch gives what a node's chunks give (a batch once kept the old calibrator to its end and dropped the
    field)."""
    rec = moving(duration=40.0, seed=3)
    mag = delayed_field(rec, round(0.3 * rec.rate_hz))
    whole = EstimatorStream(create(name), GateConfig(nominal_rate=rec.rate_hz))
    q_whole, _ = whole.process_batch(rec.stamps_ns, rec.acc, rec.gyr, mag)
    parts = EstimatorStream(create(name), GateConfig(nominal_rate=rec.rate_hz))
    step = round(rec.rate_hz)
    q_parts = np.concatenate([parts.process_batch(rec.stamps_ns[a:a + step], rec.acc[a:a + step],
                                                  rec.gyr[a:a + step], mag[a:a + step])[0]
                              for a in range(0, len(rec), step)])
    assert whole.front is not None and whole.front.late_s is not None
    np.testing.assert_allclose(q_whole, q_parts, atol=1e-9)


@pytest.mark.parametrize(("seed", "lag", "start_s"), [(3, 0.3, 5.0), (4, 0.3, 20.0), (3, 0.2, 8.0)])
def test_a_calibration_restarted_at_a_late_field_s_lag_keeps_a_right_prior(seed, lag, start_s):
    """When the scan resolves a lag the calibration starts anew in mid-rotation, its history of attitudes empty: a
    reading whose attitude (``lag`` before its sample) precedes that history makes no window. Once such a reading
    made the first window, whose wrong attitude rejected a right configured calibration at once and left an estimate
    tens of µT off with a heading σ of 3° (BROAD 01 with a field 200 ms late: heading 58° off for 15 s; here the
    starts chosen in fast rotation rejected it too)."""
    rec = moving(duration=40.0, seed=seed)
    mag = delayed_field(rec, round(lag * rec.rate_hz))
    start = round(start_s * rec.rate_hz)
    cal = OnlineMagCalibrator(MagCalPrior())  # the identity: right for this field
    dt = 1.0 / rec.rate_hz
    trusted = []
    for g, m, q in zip(rec.gyr[start:], mag[start:], rec.quat_ref[start:], strict=True):
        cal.update(from_rotvec(*(float(v) * dt for v in g)), dt, tuple(float(v) for v in m), lag,
                   tuple(float(v) for v in q))
        trusted.append(cal.trusted)
    assert cal.windows >= 20
    assert all(trusted) and cal.rejected == 0
    assert np.abs(cal.theta[cal.model.p:]).max() < 1.0  # µT: the estimate's hard iron
