"""The configured calibration as a hypothesis the gyro tests (riann_ros.magcal.hypothesis, in the online calibrator):
kept and trusted on a calibrated sensor, rejected on an offset, restored when the offset goes away again."""

from __future__ import annotations

import numpy as np

from riann_ros import quaternion as quat
from riann_ros.datasets.synthetic import generate
from riann_ros.magcal.online import OnlineMagCalibrator
from riann_ros.magcal.records import SWITCH_WINDOWS, UT, MagCalPrior
from riann_ros.magcal.synthetic import distort

H_UT = np.array([15.0, -10.0, 8.0])


def feed(cal: OnlineMagCalibrator, rec, raw, track=None):
    inc = quat.from_rotvec(rec.gyr * rec.dt[:, None]).tolist()
    for d, dt, m, q in zip(inc, rec.dt.tolist(), raw.tolist(), rec.quat_ref.tolist(), strict=True):
        cal.update(tuple(d), dt, tuple(m), 0.0, tuple(q))
        if track is not None:
            track.append((cal.trusted, cal.test.p_holds, cal.heading_sd_rad(tuple(q), (0.0, 20e-6, -40e-6))))


def recording(seed: int = 0, duration: float = 60.0):
    rec = generate(duration=duration, rate=100.0, seed=seed, bias=0.0, gyr_noise=0.002)
    return rec


def test_a_right_calibration_holds_and_its_doubt_vanishes():
    rec = recording()
    raw = distort(rec.quat_ref, H_UT * UT, noise_t=0.4e-6, seed=1)
    cal = OnlineMagCalibrator(MagCalPrior(hard_iron_t=tuple(H_UT * UT)))
    track: list = []
    feed(cal, rec, raw, track)
    assert cal.trusted and cal.windows > 20 and cal.test.p_holds > 1.0 - 1e-6
    assert track[0][2] > 0.5  # before any window: unverified (σ of radians)
    assert track[-1][2] == 0.0  # verified: the calibration adds nothing to the heading
    assert cal.status().prior_holds


def test_a_wrong_calibration_is_rejected_within_a_few_windows_and_the_estimate_takes_over():
    rec = recording()
    raw = distort(rec.quat_ref, H_UT * UT, noise_t=0.4e-6, seed=1)
    cal = OnlineMagCalibrator()  # configured: no hard iron
    track: list = []
    feed(cal, rec, raw, track)
    assert not cal.trusted and not cal.status().prior_holds
    first = next(i for i, t in enumerate(track) if not t[0])
    assert rec.t[first] < 15.0  # a few windows of motion
    assert np.abs(np.array(cal.calibration().hard_iron_t) / UT - H_UT).max() < 1.0
    assert track[-1][2] < np.radians(2.5)  # calibrated: its own σ, small


def test_a_rejected_calibration_comes_back_when_the_offset_goes():
    """A magnet attached (the configured calibration rejected) and taken off again: SWITCH_WINDOWS windows that
    agree with the configured calibration restore it, and the field is used as configured again."""
    rec = recording(duration=90.0)
    raw = distort(rec.quat_ref, np.zeros(3), noise_t=0.4e-6, seed=1)
    on = (rec.t > 5.0) & (rec.t < 35.0)
    raw[on] += H_UT * UT
    cal = OnlineMagCalibrator()
    track: list = []
    feed(cal, rec, raw, track)
    trusted = np.array([t[0] for t in track])
    assert not trusted[(rec.t > 20.0) & (rec.t < 35.0)].any()  # rejected while the magnet is on
    assert trusted[-1] and cal.windows >= 1 and SWITCH_WINDOWS > 1  # restored after it came off


def wobble(seconds: float = 120.0, amplitude_deg: float = 12.0, rate: float = 100.0):
    """A sensor that only wobbles (a phone held still, a robot on a rough floor): rotations of at most
    ``amplitude_deg`` about varying axes, slow; (gyro increments, attitudes, dt)."""
    t = np.arange(int(seconds * rate)) / rate
    a = np.radians(amplitude_deg)
    rv = np.column_stack([a * np.sin(2 * np.pi * 0.31 * t), a * np.sin(2 * np.pi * 0.23 * t + 1.0),
                          0.5 * a * np.sin(2 * np.pi * 0.17 * t + 2.0)])
    q = quat.from_rotvec(rv)
    inc = quat.multiply(quat.conjugate(q[:-1]), q[1:])
    return np.vstack([[1.0, 0.0, 0.0, 0.0], inc]), q, np.full(len(t), 1.0 / rate)


def feed_wobble(cal: OnlineMagCalibrator, inc, q, dt, raw) -> None:
    for d, h, m, a in zip(inc.tolist(), dt.tolist(), raw.tolist(), q.tolist(), strict=True):
        cal.update(tuple(d), h, tuple(m), 0.0, tuple(a))


def test_a_wobble_rejects_a_wrong_calibration_no_window_of_it_decisive_alone():
    """Small slow rotations: each window says little (none fails the configured calibration on its own), all of them
    together reject it; the same motion keeps a right one."""
    inc, q, dt = wobble()
    raw = distort(q, H_UT * UT, noise_t=0.4e-6, seed=2)
    wrong = OnlineMagCalibrator()
    feed_wobble(wrong, inc, q, dt, raw)
    assert wrong.windows >= 20  # windows close at the swings' ends
    assert not wrong.trusted
    right = OnlineMagCalibrator(MagCalPrior(hard_iron_t=tuple(H_UT * UT)))
    feed_wobble(right, inc, q, dt, raw)
    assert right.trusted and right.test.p_holds > 0.99


def test_two_disturbed_windows_do_not_reject_a_right_calibration():
    rec = recording()
    raw = distort(rec.quat_ref, H_UT * UT, noise_t=0.4e-6, seed=1)
    for t0 in (20.0, 40.0):  # a magnet passing by twice, 50 ms each: at most one window's end each time
        raw[(rec.t >= t0) & (rec.t < t0 + 0.05)] += np.array([30.0, -20.0, 25.0]) * UT
    cal = OnlineMagCalibrator(MagCalPrior(hard_iron_t=tuple(H_UT * UT)))
    track: list = []
    feed(cal, rec, raw, track)
    assert all(t[0] for t in track)


def test_windows_that_observe_nothing_of_the_difference_do_not_restore_a_rejected_calibration():
    """Rejected on rich motion (an offset along x), then turning about x only: those windows agree with the configured
    calibration and with the estimate alike (x is their rotation axis), so they are no evidence that the offset went."""
    rec = recording()
    h = np.array([20.0, 0.0, 0.0])
    raw = distort(rec.quat_ref, h * UT, noise_t=0.4e-6, seed=1)
    cal = OnlineMagCalibrator()
    feed(cal, rec, raw)
    assert not cal.trusted
    cal.restart()
    t = np.arange(6000) / 100.0
    ang = np.radians(60.0) * np.sin(2 * np.pi * 0.4 * t)  # swinging about the sensor's x axis
    q = quat.from_rotvec(np.column_stack([ang, np.zeros_like(ang), np.zeros_like(ang)]))
    inc = np.vstack([[1.0, 0.0, 0.0, 0.0], quat.multiply(quat.conjugate(q[:-1]), q[1:])])
    feed_wobble(cal, inc, q, np.full(len(t), 0.01), distort(q, h * UT, noise_t=0.4e-6, seed=3))
    assert not cal.trusted
    assert np.abs(np.array(cal.calibration().hard_iron_t) / UT - h).max() < 1.5


def test_the_estimate_is_used_as_soon_as_the_windows_make_the_configured_calibration_the_less_probable():
    """A wrong configured calibration: the readings get the estimate from the window that makes it the less probable
    hypothesis on, before the test has rejected it for good (which waits for evidence beyond the two windows that
    contradict it most); a right one keeps being used."""
    rec = recording()
    raw = distort(rec.quat_ref, H_UT * UT, noise_t=0.4e-6, seed=1)
    cal = OnlineMagCalibrator()
    states = []
    inc = quat.from_rotvec(rec.gyr * rec.dt[:, None]).tolist()
    for d, dt, m, q in zip(inc, rec.dt.tolist(), raw.tolist(), rec.quat_ref.tolist(), strict=True):
        cal.update(tuple(d), dt, tuple(m), 0.0, tuple(q))
        states.append((cal.trusted, cal.test.holds, cal.test.p_holds))
    first = next(i for i, s in enumerate(states) if not s[0])
    assert states[first][1] and states[first][2] < 0.5  # in use: the estimate; rejected for good: not yet
    assert not states[-1][1]


def swings(axes: list[np.ndarray], seconds_each: float = 2.0, amplitude_deg: float = 70.0, rate: float = 100.0):
    """Swings out and back about each of ``axes`` in turn (sensor frame, from the level attitude): (increments,
    attitudes, dt)."""
    n = int(seconds_each * rate)
    s = np.radians(amplitude_deg) * np.sin(np.pi * np.arange(n) / n)
    rv = np.vstack([np.outer(s, a) for a in axes])
    q = quat.from_rotvec(rv)
    inc = np.vstack([[1.0, 0.0, 0.0, 0.0], quat.multiply(quat.conjugate(q[:-1]), q[1:])])
    return inc, q, np.full(len(rv), 1.0 / rate)


def test_windows_both_calibrations_explain_do_not_hold_back_the_restore():
    """The magnet along x taken off, then swings about x (windows that observe nothing of it, explained by the
    configured calibration and the estimate alike) between swings about y (windows that tell the two apart): the
    swings about x are evidence for neither, so the ones about y restore the configured calibration."""
    rec = recording()
    h = np.array([20.0, 0.0, 0.0])
    cal = OnlineMagCalibrator()
    feed(cal, rec, distort(rec.quat_ref, h * UT, noise_t=0.4e-6, seed=1))
    assert not cal.trusted and not cal.test.holds  # the magnet found
    cal.restart()
    x, y = np.array([1.0, 0.0, 0.0]), np.array([0.0, 1.0, 0.0])
    inc, q, dt = swings([x, y] * (2 * SWITCH_WINDOWS))
    feed_wobble(cal, inc, q, dt, distort(q, np.zeros(3), noise_t=0.4e-6, seed=3))  # the magnet is off
    assert cal.trusted
