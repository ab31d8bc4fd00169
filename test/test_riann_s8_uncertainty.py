"""riann_ros/estimators/riann/s8_uncertainty.py: each output's σ, per sample as in a block, never feeding back, each
formula one kernel for the stage and the fit."""

from __future__ import annotations

import math

import numpy as np
import pytest
from helpers_mag import rot_z, static
from helpers_riann import outputs_of, still_then_turning
from hypothesis import given, settings
from hypothesis import strategies as st

from riann_ros import quaternion as quat
from riann_ros.defaults import MAG_HEADING_SD_DEG, YAW_FREE_SD_DEG
from riann_ros.estimators import create
from riann_ros.estimators.riann import RiannEstimator
from riann_ros.estimators.riann.s8_uncertainty import (
    FEATURES,
    FREE,
    HELD,
    MAG_SD,
    USED,
    YAW_FEATURES,
    YAW_FREE_SD,
    heading_sigma,
    heading_var,
    inclination_sigma,
    inclination_var,
)
from riann_ros.stream import EstimatorStream, GateConfig

RATE = 200.0


def test_riann_sigma_batch_equals_per_sample_and_grows_with_the_copies_spread():
    n = 1200
    acc, gyr, dt = still_then_turning(n)
    est = RiannEstimator()
    q_b = est.update_batch(acc, gyr, dt)
    s_b = est.sigma(np.zeros(n, dtype=bool))
    with pytest.raises(ValueError, match="last call"):
        est.sigma(np.zeros(3, dtype=bool))
    one = RiannEstimator(model=est.model)
    s_1 = []
    for i in range(n):
        one.update(acc[i], gyr[i], dt[i])
        s_1.append(one.sigma(np.zeros(1, dtype=bool))[0])
    assert np.abs(np.array(s_1) - s_b).max() < 1e-6
    assert (s_b > 0).all() and np.allclose(s_b[:, 1], math.radians(YAW_FREE_SD_DEG))
    # at turn-on the bias is unknown (σ_b = bias_sigma_init): larger than after it has settled at rest
    assert s_b[0, 0] > 2.0 * s_b[n // 2 - 1, 0]
    f = est.last.features
    # the per-sample formula (plain floats) is the vectorised one the fit uses

    assert np.allclose(inclination_sigma(f), s_b[:, 0], rtol=1e-12)
    assert np.allclose(heading_sigma(est.last.yaw_features, s_b[:, 0]), s_b[:, 1], rtol=1e-12)
    more = f.copy()
    more[:, 0] *= 2.0
    assert (inclination_sigma(more) > inclination_sigma(f)).all()
    assert q_b.shape == (n, 4)


def test_riann_sigma_never_changes_the_attitude():
    """The attitude with stage 8 equals the attitude with its output ignored (it only reads): run twice, once
    asking for σ after every sample, once never."""
    n = 600
    acc, gyr, dt = still_then_turning(n, seed=5)
    a = RiannEstimator()
    b = RiannEstimator(model=a.model)
    q_a = np.array([a.update(acc[i], gyr[i], dt[i]) for i in range(n)])
    q_b = []
    for i in range(n):
        q_b.append(b.update(acc[i], gyr[i], dt[i]))
        b.sigma(np.zeros(1, dtype=bool))
    assert np.abs(q_a - np.array(q_b)).max() == 0.0


def test_riann_sigma_after_a_gap_is_the_fresh_network_s_until_it_has_converged():
    """A gap (longer than the gate's max_dt) restarts the network without a bridge: the output is the fresh
    network, whose σ_f (stage 6) is reported from the first sample on and decays with its re-convergence time, then
    the converged network's σ again; per sample equals batch, in σ and in the attitude."""
    from riann_ros.estimators.riann.s6_handover import FRESH_DONE, S_REST, TAU

    n = 2500
    acc, gyr, dt = still_then_turning(n, seed=7)
    cut = 1300  # a gap before this sample (in motion, which starts at sample 1250)
    batch = RiannEstimator()
    batch.update_batch(acc[:cut], gyr[:cut], dt[:cut])
    before = batch.sigma(np.zeros(cut, dtype=bool))[-1, 0]
    batch.on_gap()
    q_b = batch.update_batch(acc[cut:], gyr[cut:], dt[cut:])
    s_b = batch.sigma(np.zeros(n - cut, dtype=bool))[:, 0]
    one = RiannEstimator(model=batch.model)
    for i in range(cut):
        one.update(acc[i], gyr[i], dt[i])
    one.on_gap()
    handed = outputs_of(one.handover)
    q_1, s_1 = [], []
    for i in range(cut, n):
        q_1.append(one.update(acc[i], gyr[i], dt[i]))
        s_1.append(one.sigma(np.zeros(1, dtype=bool))[0, 0])
    assert np.abs(np.array(s_1) - s_b).max() < 1e-6  # the network's call-length rounding (BENCHMARKS, network)
    assert np.abs(np.array(q_1) - q_b).max() < 1e-6
    # the fresh network's σ: at least S_REST at the restart, far above the converged network's σ before the gap
    assert s_b[0] >= math.radians(S_REST) and s_b[0] > 3.0 * before
    peak = int(np.argmax(s_b))  # it grows while faster rotation is seen, then decays with TAU
    k = peak + round(2 * TAU * RATE)
    assert s_b[k] < 0.2 * s_b[peak]
    # ended once below FRESH_DONE (deg): the base model again, as it was before the gap
    assert one.handover.fresh is None and batch.handover.fresh is None
    young = [h.fresh_sd_deg[0] for h in handed if h.fresh_sd_deg[0]]
    assert handed[-1].fresh_sd_deg[0] == 0.0 and min(young) < FRESH_DONE
    # without the gap the same samples report the converged network's σ: far below at the restart, alike at the end
    plain = RiannEstimator(model=batch.model)
    plain.update_batch(acc, gyr, dt)
    s_p = plain.sigma(np.zeros(n, dtype=bool))[cut:, 0]
    assert s_p[0] < 0.5 * s_b[0] and abs(s_b[-1] - s_p[-1]) < 0.5 * s_p[-1]


def test_riann_reports_its_heading_state_through_the_stream_the_others_none():

    n = 600
    acc, gyr, _ = still_then_turning(n, seed=2)
    mag = np.tile([0.0, 2e-5, -4e-5], (n, 1))
    mag[:100] = mag[400:] = np.nan
    stamps = (np.arange(n) * 1e9 / RATE).astype(np.int64) + 10**9
    for name in ("riann", "vqf"):
        est = create(name)
        st = EstimatorStream(est, GateConfig())
        st.process_batch(stamps, acc, gyr, mag)
        if name == "vqf":
            assert np.isnan(st.batch_state).all()
            continue
        assert np.array_equal(st.batch_state, est.heading_state())  # one run, no restart: the last call's
        assert (st.batch_state[:100] == 0.0).all() and (st.batch_state[150:400] == 1.0).all()
        assert (st.batch_state[400:] == 2.0).all()


def test_riann_heading_sigma_follows_the_field():
    """9D: 180° before the first field, the field's σ (with the tilt's share and the bias drift the correction leaves)
    while it corrects, growing with the gyro's drift while it is absent; the per-sample formula equals the vectorised
    one."""
    n = 2400
    acc, gyr, dt = still_then_turning(n, seed=9)
    mag = np.tile([0.0, 2e-5, -4e-5], (n, 1))
    mag[:100] = np.nan  # no field yet
    mag[1600:] = np.nan  # the field goes away
    est = RiannEstimator(mag_calibration=False)  # (a field fixed in the sensor frame: the calibration would learn it)
    est.update_batch(acc, gyr, dt, mag)
    s = est.sigma(np.isfinite(mag).all(axis=1))
    yf = est.last.yaw_features
    assert (yf[:100, 0] == FREE).all() and (yf[200:1600, 0] == USED).all() and (yf[1600:, 0] == HELD).all()
    assert np.allclose(s[:100, 1], math.radians(YAW_FREE_SD_DEG))
    assert (yf[:, 1] == 0.0).all()  # no hole, no bridge
    tilt = yf[:, 3] * s[:, 0]  # the tilt compensation's share: tan(dip) σ_i, dip 63.4° here
    assert ((yf[200:, 3] > 1.5) & (yf[200:, 3] < 2.2)).all()  # the learned reference dip, about 63°
    # while the field corrects, the heading keeps the bias drift the correction has not yet removed (the running
    # mean of the start here: it lags by about half the drift since the first field)
    assert (yf[200:1600, 2] > 0.0).all()
    assert np.allclose(np.sqrt(s[200:1600, 1] ** 2 - tilt[200:1600] ** 2 - yf[200:1600, 2] ** 2), MAG_SD)
    drift = np.sqrt(s[1600:, 1] ** 2 - tilt[1600:] ** 2 - MAG_SD**2)
    assert yf[1599, 2] < drift[0] < drift[-1] < math.radians(180.0)
    assert np.allclose(heading_sigma(yf, s[:, 0]), s[:, 1], rtol=1e-12)


def test_riann_heading_sigma_after_a_hole_and_a_gap() -> None:
    """RIANN in 9D: a bridged hole adds K_BRIDGE × the bridge's σ to the heading's σ, and each correction toward the
    field with gain k leaves (1 − k) of it (re-acquiring, the first fields weigh a lot); after a gap (no bridge)
    the heading is unknown (180°) until a field sets it again, and stays so while none comes."""
    q_a = quat.from_rotvec(np.radians([10.0, 5.0, 0.0]))
    q_b = quat.multiply(rot_z(math.radians(2.0)), q_a)  # a small turn inside the hole: the bridge is kept
    a, b = static(q_a, 1500, seed=1), static(q_b, 300, seed=2)
    assert a.mag is not None and b.mag is not None
    est = create("riann", mag_calibration=False)  # the σ of holes and gaps (the calibration: test_magcal_estimators)
    est.update_batch(a.acc, a.gyr, a.dt, a.mag)
    s_a = est.sigma(np.ones(1500, dtype=bool))[-1]
    headings = outputs_of(est.heading)
    for i in range(100):  # the node's path, a sample at a time
        est.update(b.acc[i], b.gyr[i], 0.3 if i == 0 else float(b.dt[i]), b.mag[i])
    gain = [h.gain[0] for h in headings]
    x_one = est.last.yaw_features[0, 1]
    est2 = create("riann", model=est.model, mag_calibration=False)
    est2.update_batch(a.acc, a.gyr, a.dt, a.mag)
    est2.update_batch(b.acc[:100], b.gyr[:100], np.concatenate([[0.3], b.dt[1:100]]), b.mag[:100])
    yf, s = est2.last.yaw_features, est2.sigma(np.ones(100, dtype=bool))
    k = np.array(gain)
    assert (yf[:, 0] == USED).all() and k[1] > 10 * 0.01 / 9.0  # re-acquiring: far above dt / tau_mag
    bridge = yf[0, 1] / (1.0 - k[0])  # the bridge's σ (rad) before the first field after it
    assert math.radians(1.0) <= bridge < math.radians(1.5)  # the bridge's floor: at rest on either side
    assert np.allclose(yf[:, 1], bridge * np.cumprod(1.0 - k), rtol=1e-6, atol=1e-12)
    assert x_one == pytest.approx(yf[-1, 1], rel=1e-6, abs=1e-12)  # per sample as in a block
    assert s[0, 1] > s_a[1] and s[-1, 1] < s[0, 1]
    assert np.allclose(heading_sigma(yf, s[:, 0]), s[:, 1], rtol=1e-12)
    # a gap: the heading is unknown until the next field; without one it stays unknown
    est2.on_gap()
    est2.update_batch(b.acc[100:200], b.gyr[100:200], b.dt[100:200], np.full((100, 3), np.nan))
    assert (est2.last.yaw_features[:, 0] == FREE).all()
    assert np.allclose(est2.sigma(np.zeros(100, dtype=bool))[:, 1], math.pi)
    est2.update_batch(b.acc[200:], b.gyr[200:], b.dt[200:], b.mag[200:])
    yg = est2.last.yaw_features
    # the carried share: only the doubt of the field's timing the 2° turn in the hole left (magcal/lag.py)
    assert yg[0, 0] == USED and (yg[:, 0] != HELD).all() and yg[0, 1] == 0.0 and yg[0, 2] < math.radians(0.5)


def test_riann_heading_sigma_stays_wide_when_the_field_returns_only_after_the_reacquisition() -> None:
    """After a gap the heading re-acquires the field for tau_mag s. A field that only comes back after that pulls
    the heading in at dt / tau_mag, so the heading is still as unknown as after the gap: its σ stays near 180° and
    shrinks by (1 − k) per correction, not down to the field's σ at once. (A missing field does not run the
    re-acquisition's clock; a rejected one does.)"""
    q_a = quat.from_rotvec(np.radians([10.0, 5.0, 0.0]))
    a, b = static(q_a, 1000, seed=1), static(q_a, 1400, seed=2)
    assert a.mag is not None and b.mag is not None
    est = create("riann", mag_calibration=False)  # at rest the calibration's doubt would stay (test_magcal_*)
    est.update_batch(a.acc, a.gyr, a.dt, a.mag)
    est.on_gap()
    mag = b.mag.copy()
    mag[:1000] *= 2.0  # 10 s of a disturbed field (rejected): longer than tau_mag (9 s)
    headings = outputs_of(est.heading)
    est.update_batch(b.acc, b.gyr, b.dt, mag)
    s = np.degrees(est.sigma(np.ones(len(mag), dtype=bool))[:, 1])
    k = np.array(headings[0].gain)
    first = int(np.argmax(k > 0.0))  # the field accepted again (after half a second undisturbed)
    assert 1000 < first < 1100 and np.allclose(s[:first], 180.0) and k[first] == pytest.approx(0.01 / 9.0)
    assert s[first] > 170.0 and 120.0 < s[-1] < s[first]
    assert s[-1] == pytest.approx(180.0 * np.prod(1.0 - k[first:]), rel=0.02)


@settings(max_examples=100, deadline=None)
@given(st.lists(st.floats(0.0, 3.0), min_size=4, max_size=4), st.lists(st.floats(0.0, 2.0), min_size=3, max_size=3),
       st.sampled_from([FREE, USED, HELD]))
def test_the_stage_and_the_fit_share_each_formula(f, y, state):
    """What the stage gives a sample (plain floats) is what the fit's vectorised σ gives its features."""
    si = math.sqrt(inclination_var(*f))
    assert inclination_sigma(np.array([f]))[0] == pytest.approx(si, rel=1e-12)  # numpy's and math's round-off
    yf = np.array([[state, *y]])
    want = YAW_FREE_SD if state == FREE else min(math.sqrt(heading_var(si, y[0], y[1], y[2])), YAW_FREE_SD)
    assert heading_sigma(yf, np.array([si]))[0] == pytest.approx(want, rel=1e-12)
    assert len(FEATURES) == 4 and len(YAW_FEATURES) == 4


def test_the_field_heading_sigma_is_the_fitted_default():
    assert MAG_SD == math.radians(MAG_HEADING_SD_DEG) and MAG_HEADING_SD_DEG == 2.5
