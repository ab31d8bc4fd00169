"""The magnetometer calibration core (:mod:`riann_ros.magcal`): the window constraint is exact, known hard and soft
iron are recovered online and offline, a rotation about one axis moves only what it observes, nothing moves at rest
or in straight motion, disturbed windows are rejected, the heading σ covers the error it describes, and the state."""

from __future__ import annotations

import math

import numpy as np
import pytest

from riann_ros import quaternion as quat
from riann_ros.datasets.synthetic import generate
from riann_ros.magcal.model import CalModel
from riann_ros.magcal.offline import fit_recording, shared_noise, windows_of
from riann_ros.magcal.online import OnlineMagCalibrator
from riann_ros.magcal.records import CALIBRATED, CONVERGING, UNCALIBRATED, UT, WINDOW_MAX_S, MagCalPrior
from riann_ros.magcal.synthetic import FIELD_ENU_T, distort, ground_robot
from riann_ros.rotations import rotate

H_TRUE = np.array([20.0, 0.0, -10.0])  # µT
S_SYM = np.array([[1 / 1.12, 0.04, 0.0], [0.04, 1 / 0.9, 0.03], [0.0, 0.03, 1.0]])  # symmetric soft iron
S_FULL = np.array([[1 / 1.1, 0.05, 0.0], [0.0, 1 / 0.9, 0.05], [0.02, 0.0, 1.0]])  # with a misalignment


def rich_motion(seconds: float = 120.0, seed: int = 3):
    return generate(duration=seconds, rate=200, motion="rotation", bias=0.0, gyr_noise=0.002, seed=seed)


def run(cal: OnlineMagCalibrator, rec, raw, every: int = 0):
    """Feed a recording; returns the calibrated fields (N, 3) and, every ``every`` samples, (t, h µT)."""
    inc = quat.from_rotvec(rec.gyr * rec.dt[:, None]).tolist()
    out = np.full((len(rec), 3), np.nan)
    snaps = []
    for i, (d, dt, m, q) in enumerate(zip(inc, rec.dt.tolist(), raw.tolist(), rec.quat_ref.tolist(), strict=True)):
        u = cal.update(tuple(d), dt, tuple(m) if np.all(np.isfinite(m)) else None, 0.0, tuple(q))
        if u is not None:
            out[i] = u
        if every and i % every == 0:
            snaps.append((float(rec.t[i]), np.array(cal.calibration().hard_iron_t) / UT))
    return out, snaps


def scale_free_error(s_est: np.ndarray, s_true: np.ndarray) -> float:
    """The largest relative entry error after the common scale (unobservable without the field's strength)."""
    k = float(np.sum(s_est * s_true) / np.sum(s_est * s_est))
    return float(np.abs(k * s_est - s_true).max() / np.abs(s_true).max())


def test_window_constraint_is_exact_for_the_true_calibration():
    rec = rich_motion(30.0)
    raw = distort(rec.quat_ref, H_TRUE * UT, S_FULL)
    ws, _ = windows_of(np.zeros((len(rec), 3)), rec.dt, raw)  # no rotation: no window
    assert len(ws) == 0
    # exact attitude increments: integrate the reference instead of the gyro
    q = rec.quat_ref
    rv = quat.from_rotvec(np.zeros(3))
    assert rv.shape == (4,)
    inc = quat.multiply(quat.conjugate(np.vstack([q[:1], q[:-1]])), q)
    gyr = quat.rotate(np.array([1.0, 0, 0, 0]), np.zeros((len(q), 3)))
    ang = 2 * np.arctan2(np.linalg.norm(inc[:, 1:], axis=1), inc[:, 0])
    axis = inc[:, 1:] / np.maximum(np.linalg.norm(inc[:, 1:], axis=1, keepdims=True), 1e-300)
    gyr = axis * (ang / rec.dt)[:, None]
    ws, _ = windows_of(gyr, rec.dt, raw)
    assert len(ws) > 100
    for model in ("full", "symmetric"):
        m = CalModel(model, np.eye(3))  # type: ignore[arg-type]
        # θ of the truth up to the unobservable scale: ⟨A, I⟩ = 3
        k = 3.0 / np.trace(S_FULL)
        a = k * S_FULL
        if model == "symmetric":
            continue  # S_FULL is not symmetric: only the full model holds it
        theta = np.r_[m.basis.T @ (a - np.eye(3)).reshape(9), a @ H_TRUE]
        j, r0 = m.rows(ws)
        r = r0 + j @ theta
        assert np.abs(r).max() < 1e-6 * np.abs(r0).max() + 1e-9


@pytest.mark.slow
@pytest.mark.parametrize(("model", "s_true"), [("symmetric", S_SYM), ("full", S_FULL)])
def test_known_hard_and_soft_iron_recovered_online_and_offline(model, s_true):
    rec = rich_motion()
    raw = distort(rec.quat_ref, H_TRUE * UT, s_true, noise_t=0.3e-6)
    cal = OnlineMagCalibrator(soft_iron_model=model)
    run(cal, rec, raw)
    c = cal.calibration()
    assert np.linalg.norm(np.array(c.hard_iron_t) / UT - H_TRUE) < 0.6
    assert scale_free_error(np.array(c.soft_iron).reshape(3, 3), s_true) < 0.015
    assert cal.state == CALIBRATED and cal.rejected < 3
    off = fit_recording(rec.gyr, rec.dt, raw, soft_iron_model=model, acc=rec.acc)  # the acceptance
    h_err = np.array(off.calibration.hard_iron_t) / UT - H_TRUE
    assert np.linalg.norm(h_err) < 0.5
    assert scale_free_error(np.array(off.calibration.soft_iron).reshape(3, 3), s_true) < 0.01
    assert np.all(np.abs(h_err) < 3.0 * np.array(off.calibration.hard_iron_sd_t) / UT + 0.05)  # σ is honest
    assert off.field_norm_sd_ut < 1.0  # the calibrated readings lie on a sphere ...
    k = 3.0 / np.trace(s_true)  # ... of the field's radius at the calibration's scale (trace S = 3)
    assert off.field_norm_ut == pytest.approx(np.linalg.norm(FIELD_ENU_T) / UT * k, rel=0.01)


#: a distortion with skew (reading = D m + h): its calibration S = D⁻¹ is not symmetric, it holds a rotation of 2.6°
#: (1.4–1.6° about each axis, beyond the 1° misalignment prior) that only the full model represents
D_SKEW = np.array([[1.15, 0.05, 0.0], [0.0, 0.85, 0.05], [0.05, 0.0, 1.0]])


@pytest.mark.slow
def test_non_symmetric_soft_iron_recovered_offline():
    """The misalignment is observed by the windows (each window's residual carries it) about as well as the prior
    knows it once their information is divided by the windows covering each stretch (~120); their residuals are
    shared by far fewer, so the fit moves it and the hard iron is not biased by an unmodelled rotation."""
    s_true = np.linalg.inv(D_SKEW)
    for seed in (4, 5, 6):
        rec = rich_motion(seed=seed)
        raw = distort(rec.quat_ref, H_TRUE * UT, s_true, noise_t=0.3e-6, seed=seed)
        off = fit_recording(rec.gyr, rec.dt, raw, acc=rec.acc)  # the default, full soft-iron model
        assert np.linalg.norm(np.array(off.calibration.hard_iron_t) / UT - H_TRUE) < 0.5
        assert scale_free_error(np.array(off.calibration.soft_iron).reshape(3, 3), s_true) < 0.01
        assert off.field_norm_sd_ut < 1.0
    # the symmetric model cannot hold that rotation: the hard iron takes up part of it
    sym = fit_recording(rec.gyr, rec.dt, raw, soft_iron_model="symmetric", acc=rec.acc)
    assert np.linalg.norm(np.array(sym.calibration.hard_iron_t) / UT - H_TRUE) > 0.5


def test_shared_noise_counts_correlated_windows():
    rng = np.random.default_rng(0)
    white = rng.normal(size=(6000, 3))
    assert shared_noise(white.reshape(-1), 100.0) == pytest.approx(1.0, abs=0.3)
    # each residual the mean of 20 consecutive white draws: 20 windows share each one's noise
    shared = np.cumsum(rng.normal(size=(6020, 3)), axis=0)
    shared = (shared[20:] - shared[:-20]) / 20.0
    assert shared_noise(shared.reshape(-1), 100.0) == pytest.approx(20.0, rel=0.3)
    assert shared_noise(shared.reshape(-1), 8.0) == 8.0  # at most the windows covering a stretch


def robot():
    """Turns about the vertical with a tilted mount, then rest, then straight driving."""
    phases = [("rest", 3.0, 0.0)] + [("turn", 6.0, 30.0), ("straight", 3.0, 0.0), ("turn", 6.0, -45.0)] * 6
    phases += [("rest", 20.0, 0.0), ("straight", 20.0, 0.0)]
    rec = ground_robot(phases, rate_hz=100.0, mount_rpy_deg=(10.0, -5.0, 30.0), gyr_noise=0.003, seed=1)
    t_turns = sum(p[1] for p in phases[:-2])
    return rec, t_turns


@pytest.mark.slow
@pytest.mark.parametrize("model", ["none", "symmetric", "full"])
def test_rotation_about_one_axis_moves_only_what_it_observes(model):
    rec, t_turns = robot()
    raw = distort(rec.quat_ref, H_TRUE * UT, noise_t=0.4e-6, seed=2)
    cal = OnlineMagCalibrator(soft_iron_model=model)
    u, snaps = run(cal, rec, raw, every=50)
    axis = quat.rotate(quat.conjugate(rec.quat_ref[0]), np.array([0.0, 0.0, 1.0]))  # the turning axis, sensor
    h_turns = next(h for t, h in snaps if t >= t_turns)
    err = h_turns - H_TRUE
    along = err @ axis
    assert abs(h_turns @ axis) < 0.5  # the component along the axis stays at its prior (0) ...
    assert abs(along) > 5.0  # ... which is not the truth (the test would pass trivially otherwise)
    assert np.linalg.norm(err - along * axis) < 0.6  # the components across it converge
    # at rest and driving straight nothing moves, not even by rounding (once the last turn's window has closed)
    after = [h for t, h in snaps if t >= t_turns + WINDOW_MAX_S + 0.5]
    assert len(after) > 50
    assert all(np.array_equal(h, after[0]) for h in after)
    # the heading of the tilt-compensated field is right, and nothing diverged
    mw = quat.rotate(rec.quat_ref[-1000:], u[-1000:])  # the last 10 s (a reading's noise is 1° of heading)
    assert abs(np.degrees(np.mean(np.arctan2(mw[:, 0], mw[:, 1])))) < 1.5
    assert np.all(np.isfinite(cal.covariance))


def test_no_drift_at_rest_and_straight():
    rec = ground_robot([("rest", 30.0, 0.0), ("straight", 30.0, 0.0)], rate_hz=200.0, gyr_noise=0.003)
    raw = distort(rec.quat_ref, H_TRUE * UT, noise_t=0.5e-6)
    prior = MagCalPrior(hard_iron_t=(15e-6, 2e-6, -8e-6))
    cal = OnlineMagCalibrator(prior)
    theta0 = cal.theta.copy()
    run(cal, rec, raw)
    assert cal.windows == 0 and cal.s.est.added == 0
    assert np.array_equal(cal.theta, theta0)
    assert cal.state == UNCALIBRATED


@pytest.mark.slow
def test_disturbance_windows_are_rejected():
    rec = rich_motion(120.0, seed=5)
    raw = distort(rec.quat_ref, H_TRUE * UT, S_SYM, noise_t=0.3e-6)
    dist = (rec.t >= 80.0) & (rec.t < 88.0)
    raw_d = raw + np.where(dist[:, None], np.array([25e-6, -15e-6, 10e-6]), 0.0)  # a magnet carried by for 8 s
    clean = OnlineMagCalibrator(soft_iron_model="symmetric")
    _, snaps_c = run(clean, rec, raw, every=200)
    cal = OnlineMagCalibrator(soft_iron_model="symmetric")
    _, snaps = run(cal, rec, raw_d, every=200)
    assert cal.rejected >= 5 and cal.s.switches == 0
    h_before = next(h for t, h in snaps if t >= 80.0)
    h_in = [h for t, h in snaps if 80.0 <= t < 90.0]
    assert max(np.linalg.norm(h - h_before) for h in h_in) < 0.3  # the estimate holds through the disturbance
    assert np.linalg.norm(snaps[-1][1] - snaps_c[-1][1]) < 0.3


@pytest.mark.slow
def test_a_changed_magnetic_situation_replaces_the_estimate():
    """A magnet attached during the first 40 s of motion (BROAD trial 33 has one): the estimate learns it (it is a
    hard iron while attached); once it is removed, the consistently rejected windows replace it."""
    rec = rich_motion(120.0, seed=6)
    raw = distort(rec.quat_ref, H_TRUE * UT, noise_t=0.3e-6)
    magnet = np.array([-5.0, 8.0, 25.0])
    raw = raw + np.where((rec.t < 40.0)[:, None], magnet * UT, 0.0)
    cal = OnlineMagCalibrator(soft_iron_model="symmetric")
    _, snaps = run(cal, rec, raw, every=200)
    h_attached = next(h for t, h in snaps if t >= 39.0)
    assert np.linalg.norm(h_attached - H_TRUE - magnet) < 1.0
    assert cal.s.switches == 1 and cal.rejected >= 20
    assert np.linalg.norm(snaps[-1][1] - H_TRUE) < 0.6


@pytest.mark.slow
def test_heading_sigma_covers_the_calibration_error_and_the_state_moves_on():
    rec = rich_motion(120.0, seed=7)
    raw = distort(rec.quat_ref, H_TRUE * UT, S_SYM, noise_t=0.3e-6, seed=4)
    cal = OnlineMagCalibrator(soft_iron_model="symmetric")
    assert cal.state == UNCALIBRATED
    inc = quat.from_rotvec(rec.gyr * rec.dt[:, None]).tolist()
    true_w = np.asarray(FIELD_ENU_T)
    z, states = [], set()
    for i in range(len(rec)):
        q = tuple(rec.quat_ref[i])
        u = cal.update(tuple(inc[i]), float(rec.dt[i]), tuple(raw[i]), 0.0, q)  # type: ignore[arg-type]
        states.add(cal.state)
        assert u is not None
        mw = rotate(q, u)  # type: ignore[arg-type]
        err = math.remainder(math.atan2(mw[0], mw[1]) - math.atan2(true_w[0], true_w[1]), 2 * math.pi)
        if cal.windows and i % 10 == 0:
            z.append(err / cal.heading_sd_rad(q, mw))  # type: ignore[arg-type]
    z_arr = np.abs(np.array(z))
    assert states == {UNCALIBRATED, CONVERGING, CALIBRATED}
    assert cal.converged_after_s is not None and 0.0 < cal.converged_after_s < 100.0
    st = cal.status()  # what the node's diagnostics show
    assert st.state == CALIBRATED and st.heading_sd_bound_rad <= math.radians(2.5) and st.windows == cal.windows
    assert all(0.0 < sd < 1e-6 for sd in st.hard_iron_sd_t) and st.converged_after_s == cal.converged_after_s
    assert 0.4e-6 < cal.field_sd_t() < 2e-6  # the field's σ at the end: the hard iron's floor and a little more
    fresh = OnlineMagCalibrator()  # before any window the configured calibration is used as it is (hypothesis.py) ...
    assert fresh.trusted and fresh.field_sd_t() == 0.0
    assert math.sqrt(fresh.covariance[-1, -1]) > 40.0  # ... while the estimate's σ is the prior's 50 µT
    assert np.mean(z_arr <= 2.0) > 0.9  # the error is inside 2σ at least 90 % of the time
    assert np.mean(z_arr <= 0.1) < 0.9  # and σ is not uselessly wide


def test_bad_readings_are_no_readings():
    rec = rich_motion(40.0, seed=8)
    raw = distort(rec.quat_ref, H_TRUE * UT, noise_t=0.3e-6)
    bad = raw.copy()
    bad[::7] = np.nan
    bad[3::11] = (1.0, 0.0, 0.0)  # saturated / wrong unit
    bad[5::13] = 0.0  # dead
    cal = OnlineMagCalibrator()
    inc = quat.from_rotvec(rec.gyr * rec.dt[:, None]).tolist()
    for i in range(len(rec)):
        cal.update(tuple(inc[i]), float(rec.dt[i]), tuple(bad[i]), 0.0, tuple(rec.quat_ref[i]))  # type: ignore[arg-type]
    assert cal.windows > 20 and cal.rejected == 0 and np.all(np.isfinite(cal.theta))
    assert np.linalg.norm(np.array(cal.calibration().hard_iron_t) / UT - H_TRUE) < 1.5


def test_latency_compensation():
    rec = rich_motion(90.0, seed=2)
    lag = 0.03  # s: the magnetometer saw the field 30 ms before its stamp
    q_lag = quat.normalize(np.array([np.interp(rec.t - lag, rec.t, rec.quat_ref[:, k]) for k in range(4)]).T)
    raw = distort(q_lag, H_TRUE * UT, noise_t=0.2e-6)
    errs = {}
    for d in (0.0, lag):
        wins, _ = windows_of(rec.gyr, rec.dt, raw, delay_s=d)
        off = fit_recording(rec.gyr, rec.dt, raw, soft_iron_model="none", delay_s=d)
        errs[d] = np.linalg.norm(np.array(off.calibration.hard_iron_t) / UT - H_TRUE)
        assert len(wins) > 100
    assert errs[lag] < 0.3 < errs[0.0] or errs[lag] < 0.5 * errs[0.0]


def test_records_refuse_bad_values():
    with pytest.raises(ValueError, match="hard_iron_t"):
        MagCalPrior(hard_iron_t=(float("nan"), 0.0, 0.0))
    with pytest.raises(ValueError, match="soft_iron"):
        MagCalPrior(soft_iron=(1.0, 0.0))
    with pytest.raises(ValueError, match="positive"):
        MagCalPrior(hard_iron_sd_t=0.0)
    with pytest.raises(ValueError, match="soft-iron model"):
        OnlineMagCalibrator(soft_iron_model="diagonal")  # type: ignore[arg-type]


def test_a_swing_closes_its_window_at_its_farthest_reading():
    """A swing out to 20° and back (never 45°): the window closes at the swing's end, once the sensor has come back
    TURN_BACK_RAD; a swing of 10° (below WINDOW_MIN_ANGLE_RAD) closes none."""
    from riann_ros.magcal.windows import TURN_BACK_RAD, Windower

    def windows(amplitude_deg: float) -> list:
        t = np.arange(400) / 100.0
        ang = np.radians(amplitude_deg) * 0.5 * (1.0 - np.cos(2.0 * np.pi * t / 4.0))  # 0 → amplitude → 0 in 4 s
        inc = quat.from_rotvec(np.column_stack([np.zeros_like(t), np.diff(ang, prepend=0.0), np.zeros_like(t)]))
        w = Windower()
        out = []
        for i, d in enumerate(inc.tolist()):
            got = w.add(tuple(d), 0.01, (float(i), 0.0, 40.0))  # the reading's x tells which sample it is
            if got is not None:
                out.append((i, got))
        return out

    (i, w), = windows(20.0)
    assert np.degrees(w.angle_rad) == pytest.approx(20.0, abs=0.1)
    assert w.m1_ut[0] == pytest.approx(200.0, abs=2.0)  # the reading at the swing's end (t = 2 s)
    assert 200 < i < 300 and np.degrees(TURN_BACK_RAD) < 20.0  # closed once the sensor came back, not at the timeout
    assert windows(10.0) == []


def test_a_slow_steady_turn_closes_its_window_at_the_timeout():
    """Turning at 6 °/s (45° would take 7.5 s): the window closes at WINDOW_MAX_S with the 30° turned by then."""
    from riann_ros.magcal.records import WINDOW_MAX_S
    from riann_ros.magcal.windows import Windower

    w = Windower()
    d = tuple(quat.from_rotvec(np.array([[0.0, 0.0, np.radians(6.0) * 0.01]]))[0])
    got = [(i, x) for i in range(1200) if (x := w.add(d, 0.01, (40.0, 0.0, 0.0))) is not None]
    assert len(got) >= 2
    first = got[0][1]
    assert first.duration_s == pytest.approx(WINDOW_MAX_S, abs=0.02)
    assert np.degrees(first.angle_rad) == pytest.approx(30.0, abs=0.2)
