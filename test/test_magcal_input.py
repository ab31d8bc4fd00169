"""riann_ros/magcal/input.py: the magnetometer input: pairing, calibration, plausibility, use_mag, declination, the
field state through the stream (the node's one-sample path against the batch reference)."""

from __future__ import annotations

import bisect
import math

import numpy as np
import pytest
from helpers_mag import (
    ESTIMATORS,
    NAN3,
    STREAM_TOL,
    field_of,
    gravity_angle,
    heading_change_deg,
    moving,
    per_sample,
    rot_z,
    sign_aligned,
    skip_without_mag,
)
from hypothesis import given, settings
from hypothesis import strategies as st

from riann_ros import quaternion as quat
from riann_ros.estimators import create
from riann_ros.magcal.input import (
    FIELD_BAD,
    FIELD_NONE,
    FIELD_NONFINITE,
    FIELD_OFF,
    FIELD_STALE,
    FIELD_USED,
    USABLE_MAX_T,
    USABLE_MIN_T,
    MagConfig,
    MagInput,
    MagPairing,
    pair_fields,
)
from riann_ros.stream import EstimatorStream, GateConfig

TIMEOUT_NS = 500_000_000  # the default mag_timeout


def jittered_stamps() -> tuple[np.ndarray, np.ndarray, np.ndarray, int]:
    """(IMU stamps at 400 Hz, mag stamps at 100 Hz with a 1.2 s hole and a repeated stamp, fields, the last mag
    stamp before the hole); both jittered, the IMU starting before the first field."""
    rng = np.random.default_rng(11)
    ms = 10**9 + np.arange(600) * 10_000_000 + rng.integers(-2_000_000, 2_000_000, 600)
    ms = ms[(ms < 2_500_000_000) | (ms >= 3_700_000_000)]  # the hole: 1.2 s > mag_timeout
    ms[100] = ms[99]  # a repeated stamp: the later reading wins
    before_hole = int(ms[ms < 2_500_000_000][-1])
    vals = 40e-6 * rng.standard_normal((len(ms), 3))
    imu = 950_000_000 + np.arange(2500) * 2_500_000 + rng.integers(-500_000, 500_000, 2500)
    # exactly on a field stamp, and just at / past the staleness limit after the hole's last reading
    extra = [int(ms[10]), before_hole + TIMEOUT_NS, before_hole + TIMEOUT_NS + 1]
    imu = np.unique(np.concatenate([imu, extra]))
    return imu.astype(np.int64), ms.astype(np.int64), vals, before_hole


def test_pair_fields_equals_pairing_at() -> None:
    imu, ms, vals, before_hole = jittered_stamps()
    paired = pair_fields(imu, ms, vals, TIMEOUT_NS)
    assert paired.shape == (len(imu), 3)

    # independent reference: the newest reading at or before the stamp, if at most TIMEOUT_NS old
    ms_list = ms.tolist()
    want = np.full((len(imu), 3), np.nan)
    for i, t in enumerate(imu.tolist()):
        k = bisect.bisect_right(ms_list, t) - 1
        if k >= 0 and t - ms_list[k] <= TIMEOUT_NS:
            want[i] = vals[k]
    np.testing.assert_array_equal(paired, want)

    # the node: readings arrive up to 25 ms ahead of the IMU stamp (a field stamped ahead of the IMU)
    pairing = MagPairing()
    lead = 25_000_000
    j = 0
    ahead = 0
    for i, t in enumerate(imu.tolist()):
        while j < len(ms) and ms_list[j] <= t + lead:
            pairing.push(ms_list[j], vals[j])
            j += 1
        ahead += int(j > 0 and ms_list[j - 1] > t)
        field, age = pairing.at(t, TIMEOUT_NS)
        k = bisect.bisect_right(ms_list, t) - 1
        if k < 0:
            assert field is None and age is None, i
        else:
            assert age == t - ms_list[k], i
            if field is None:
                assert np.isnan(paired[i]).all(), i
            else:
                np.testing.assert_array_equal(np.array(field), paired[i])
    assert ahead > 1000  # most IMU samples saw a reading stamped after their own
    assert pairing.received == len(ms)

    # the cases are there: before the first field, in the stale part of the hole, at the limit, repeated stamp
    assert np.isnan(paired[imu < ms[0]]).all() and (imu < ms[0]).any()
    stale = (imu > before_hole + TIMEOUT_NS) & (imu < 3_700_000_000)
    assert stale.sum() > 100 and np.isnan(paired[stale]).all()
    fresh = (imu > before_hole) & (imu <= before_hole + TIMEOUT_NS)
    assert fresh.sum() > 100 and np.isfinite(paired[fresh]).all()
    at_limit = int(np.flatnonzero(imu == before_hole + TIMEOUT_NS)[0])
    np.testing.assert_array_equal(paired[at_limit], vals[ms == before_hole][-1])
    assert np.isnan(paired[at_limit + 1]).all()
    on_repeat = (imu >= ms[100]) & (imu < ms[101])
    assert np.all(paired[on_repeat] == vals[100])


def test_field_stamped_ahead_and_clock_back() -> None:
    # every field stamped after the IMU sample: none is paired (never a reading from the future)
    imu = np.array([100, 200, 300], dtype=np.int64)
    ms = np.array([150, 250], dtype=np.int64)
    vals = np.array([[1e-5, 0.0, 0.0], [2e-5, 0.0, 0.0]])
    out = pair_fields(imu, ms, vals, 1000)
    assert np.isnan(out[0]).all()
    np.testing.assert_array_equal(out[1:], vals)
    pairing = MagPairing()
    for t, v in zip(ms, vals, strict=True):
        pairing.push(int(t), v)
    assert pairing.at(100, 1000) == (None, None)
    assert pairing.at(200, 1000) == ((1e-5, 0.0, 0.0), 50)
    assert pairing.at(300, 40) == (None, 50)  # stale: too old, but its age is known
    assert np.isnan(pair_fields(imu, ms, vals, 40)[2]).all()
    assert np.isnan(pair_fields(imu, np.zeros(0, np.int64), np.zeros((0, 3)), 1000)).all()
    # the magnetometer's clock goes back: older readings are forgotten
    pairing.push(120, [3e-5, 0.0, 0.0])
    assert pairing.at(300, 1000) == ((3e-5, 0.0, 0.0), 180)
    assert pairing.at(110, 1000) == (None, None)
    pairing.clear()
    assert pairing.at(300, 1000) == (None, None)


HARD = (3e-6, -5e-6, 2e-6)


SOFT = (1.1, 0.02, -0.01, 0.02, 0.95, 0.03, -0.01, 0.03, 1.05)


def test_calibration_applied() -> None:
    rng = np.random.default_rng(2)
    raw = 45e-6 * rng.standard_normal((50, 3))
    raw[np.linalg.norm(raw, axis=1) < 5e-6] = 30e-6  # all plausible
    want = (np.asarray(SOFT).reshape(3, 3) @ (raw - np.asarray(HARD)).T).T  # m = S (m_raw − h)
    mi = MagInput(MagConfig(mag_hard_iron=HARD, mag_soft_iron=SOFT))
    np.testing.assert_allclose(mi.prepare_batch(raw), want, rtol=1e-12, atol=1e-18)
    for r, w in zip(raw, want, strict=True):
        np.testing.assert_allclose(mi.prepare(r), w, rtol=1e-12, atol=1e-18)
    assert mi.state == FIELD_USED
    # hard iron alone, and the default (identity) passes the field as it is
    only_h = MagInput(MagConfig(mag_hard_iron=HARD)).prepare(raw[0])
    np.testing.assert_allclose(only_h, raw[0] - np.asarray(HARD), rtol=1e-12, atol=1e-18)
    np.testing.assert_allclose(MagInput().prepare(raw[0]), raw[0], rtol=0, atol=1e-18)
    # a list works as well as a tuple (a ROS double array)
    mi2 = MagInput(MagConfig(mag_hard_iron=list(HARD), mag_soft_iron=list(SOFT)))
    np.testing.assert_allclose(mi2.prepare_batch(raw), want, rtol=1e-12, atol=1e-18)
    with pytest.raises(ValueError):
        MagConfig(mag_soft_iron=(1.0, 0.0, 0.0))
    with pytest.raises(ValueError):
        MagConfig(use_mag="yes")


IMPLAUSIBLE = {
    "nan": [np.nan, 20e-6, -40e-6],
    "inf": [np.inf, 0.0, 0.0],
    "zero": [0.0, 0.0, 0.0],
    "too_large": [0.0, 0.8e-3, -0.8e-3],  # 1.13 mT: saturated or a magnet
    "too_small": [0.0, 0.5e-6, -0.5e-6],  # 0.7 µT: dead sensor or gauss read as tesla
    "gauss_units": [0.0, 0.2, -0.4],  # 0.45 T
}


@pytest.mark.parametrize("what", list(IMPLAUSIBLE))
def test_implausible_field_not_passed(what: str) -> None:
    bad = np.array(IMPLAUSIBLE[what])
    finite = bool(np.isfinite(bad).all())
    mi = MagInput()
    assert mi.state == FIELD_NONE
    assert mi.prepare(bad) is None
    # (the node's one-sample path: None is "none paired", any value a reading; the batch path: a NaN row is none)
    not_finite_states = (FIELD_NONE, FIELD_STALE, FIELD_BAD, FIELD_NONFINITE)
    assert (mi.state == FIELD_BAD) if finite else (mi.state in not_finite_states)
    good = field_of(quat.IDENTITY)
    batch = mi.prepare_batch(np.vstack([good, bad, good]))
    assert batch is not None
    assert np.isnan(batch[1]).all()
    np.testing.assert_allclose(batch[[0, 2]], [good, good], rtol=0, atol=1e-18)
    assert mi.state == FIELD_USED  # the state is that of the last row
    mi.prepare_batch(np.vstack([good, bad]))
    assert (mi.state == FIELD_BAD) if finite else (mi.state in not_finite_states)


def test_plausibility_limits_after_calibration() -> None:
    mi = MagInput()
    for norm in (USABLE_MIN_T, USABLE_MAX_T, 25e-6, 65e-6):
        m = np.array([0.0, 0.0, norm])
        np.testing.assert_array_equal(mi.prepare(m), m)  # the limits themselves are plausible
    assert mi.prepare([0.0, 0.0, USABLE_MIN_T * 0.999]) is None
    assert mi.prepare([0.0, 0.0, USABLE_MAX_T * 1.001]) is None
    # plausibility is judged on the calibrated field: a raw field equal to the hard iron is zero after it
    cal = MagInput(MagConfig(mag_hard_iron=(10e-6, 20e-6, -40e-6)))
    assert cal.prepare([10e-6, 20e-6, -40e-6]) is None
    assert cal.state == FIELD_BAD
    # ... and a reading that would be implausible raw can be fine after it (a large offset)
    cal = MagInput(MagConfig(mag_hard_iron=(2e-3, 0.0, 0.0)))
    np.testing.assert_allclose(cal.prepare([2e-3, 20e-6, -40e-6]), [0.0, 20e-6, -40e-6], rtol=0, atol=1e-15)


def test_use_mag_false_never_passes_a_field() -> None:
    good = field_of(quat.IDENTITY)
    mi = MagInput(MagConfig(use_mag="false"))
    assert mi.state == FIELD_OFF
    assert mi.prepare(good) is None
    assert mi.prepare_batch(np.tile(good, (5, 1))) is None
    assert mi.prepare(None) is None and mi.prepare_batch(None) is None
    assert mi.state == FIELD_OFF
    mi.reset()
    assert mi.state == FIELD_OFF
    # "true" passes fields like "auto"
    on = MagInput(MagConfig(use_mag="true"))
    np.testing.assert_array_equal(on.prepare(good), good)
    assert on.state == FIELD_USED


def test_state_strings_through_the_stream() -> None:
    assert FIELD_USED.startswith("9D") and all(s.startswith("6D") for s in (FIELD_OFF, FIELD_NONE, FIELD_STALE,
                                                                          FIELD_BAD))
    assert len({FIELD_USED, FIELD_OFF, FIELD_NONE, FIELD_STALE, FIELD_BAD, FIELD_NONFINITE}) == 6
    rec = moving(duration=2.0)
    assert rec.mag is not None
    s = EstimatorStream(create("vqf"), GateConfig(nominal_rate=100.0))
    assert s.mag.state == FIELD_NONE

    def step(i: int, m) -> str:
        q, r = s.process(int(rec.stamps_ns[i]), rec.acc[i], rec.gyr[i], mag=m)
        assert q is not None and r.accepted
        return s.mag.state

    assert step(0, None) == FIELD_NONE  # nothing received yet
    assert step(1, NAN3) == FIELD_NONFINITE  # a reading (the node's None is none), not finite
    assert step(2, rec.mag[2]) == FIELD_USED
    assert step(3, None) == FIELD_STALE  # had one, none fresh now
    assert step(4, NAN3) == FIELD_NONFINITE
    assert s.mag.non_finite == 2
    assert step(5, [0.0, 0.0, 0.0]) == FIELD_BAD
    assert step(6, rec.mag[6]) == FIELD_USED
    assert s.mag.samples_with_field == 2
    s.reset()
    assert s.mag.state == FIELD_NONE
    assert step(7, None) == FIELD_NONE  # after a reset nothing was received
    off = EstimatorStream(create("vqf"), GateConfig(nominal_rate=100.0), MagConfig(use_mag="false"))
    off.process(int(rec.stamps_ns[0]), rec.acc[0], rec.gyr[0], mag=rec.mag[0])
    assert off.mag.state == FIELD_OFF and off.mag.samples_with_field == 0


def test_batch_state_equals_per_sample_state() -> None:
    rec = moving(duration=3.0)
    assert rec.mag is not None
    mag = rec.mag.copy()
    mag[-1] = np.nan  # the last sample has no fresh field, earlier ones had
    gate = GateConfig(nominal_rate=100.0)
    b = EstimatorStream(create("vqf"), gate)
    b.process_batch(rec.stamps_ns, rec.acc, rec.gyr, mag)
    s = EstimatorStream(create("vqf"), gate)
    per_sample(s, rec.stamps_ns, rec.acc, rec.gyr, mag)
    assert s.mag.state == FIELD_STALE
    assert b.mag.state == s.mag.state


@pytest.mark.parametrize("name", ESTIMATORS)
def test_declination_rotates_9d_output(name: str) -> None:
    skip_without_mag(name)
    rec = moving(duration=8.0, seed=7)
    assert rec.mag is not None
    mag = rec.mag.copy()
    first = 200
    mag[:first] = np.nan
    mag[600:] = np.nan  # the field stops: the output stays referenced to true north
    gate = GateConfig(nominal_rate=100.0)
    q0, _ = EstimatorStream(create(name), gate, MagConfig(declination_deg=0.0)).process_batch(
        rec.stamps_ns, rec.acc, rec.gyr, mag)
    q10, _ = EstimatorStream(create(name), gate, MagConfig(declination_deg=10.0)).process_batch(
        rec.stamps_ns, rec.acc, rec.gyr, mag)
    tol = STREAM_TOL.get(name, 1e-9)
    np.testing.assert_allclose(q10[:first], q0[:first], rtol=0, atol=tol)  # before the first field: unchanged
    want = quat.multiply(rot_z(math.radians(-10.0)), q0[first:])
    np.testing.assert_allclose(sign_aligned(want, q10[first:]), want, rtol=0, atol=tol)
    # the rotation is about the vertical: inclination unchanged, heading by 10°
    assert gravity_angle(q0, q10).max() < 1e-6
    np.testing.assert_allclose(heading_change_deg(q0[first:], q10[first:]), 10.0, atol=1e-6)
    if name == "vqf":  # the per-sample path applies it the same way
        q1, _ = per_sample(EstimatorStream(create(name), gate, MagConfig(declination_deg=10.0)),
                           rec.stamps_ns, rec.acc, rec.gyr, mag)
        np.testing.assert_allclose(sign_aligned(q10, q1), q10, rtol=0, atol=1e-6)


@settings(max_examples=150, deadline=None)
@given(st.lists(st.floats(-2e-3, 2e-3) | st.sampled_from([0.0, np.nan, np.inf, -np.inf]), min_size=3, max_size=3),
       st.booleans())
def test_one_field_in_plain_floats_equals_the_batch_reference(m, calibrated):
    """The node's path (:meth:`MagInput.prepare`, plain floats) gives the field, or none, and the state that the
    batch path gives for a block of that one field, on random readings (tiny, huge, zero, not finite)."""
    cfg = MagConfig(mag_hard_iron=HARD, mag_soft_iron=SOFT) if calibrated else MagConfig()
    one, batch = MagInput(cfg), MagInput(cfg)
    got, want = one.prepare(m), batch.prepare_batch(np.array([m]))
    assert want is not None
    if got is None:
        assert np.isnan(want[0]).all()
    else:
        np.testing.assert_allclose(got, want[0], rtol=1e-12, atol=0)
    if np.isnan(m).all():  # the batch's "none paired"; to the node's path a reading that is not finite
        assert one.state == FIELD_NONFINITE and batch.state == FIELD_NONE
    else:
        assert one.state == batch.state
