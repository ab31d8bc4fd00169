"""Madgwick, Mahony and VQF estimators: interface, frame, dt handling, cross-checks against ahrs and vqf."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from conftest import rmse
from riann_ros import quaternion as quat
from riann_ros.estimators import create, estimator_class
from riann_ros.estimators.madgwick import DEFAULT_BETA, MadgwickEstimator
from riann_ros.estimators.mahony import DEFAULT_KI, DEFAULT_KP, MahonyEstimator
from riann_ros.estimators.vqf_estimator import VqfEstimator

NAMES = ("madgwick", "mahony", "vqf")
G = 9.81
# a runtime-changeable parameter per estimator: (name, valid new value, out-of-range value)
RUNTIME_CHANGE = {
    "madgwick": ("beta", 0.5, -0.1),
    "mahony": ("kp", 5.0, 1e6),
    "vqf": ("tau_acc", 0.5, 0.0),
}


def synthetic(
    n: int = 2000, seed: int = 0, rate: float = 100.0
) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """A smooth rotation with consistent acc (gravity + small linear acceleration) and gyr, jittered dt.

    Returns acc, gyr, dt and the true attitude (sensor → world, z up).
    """
    rng = np.random.default_rng(seed)
    dt = (1.0 / rate) * (1.0 + 0.2 * rng.uniform(-1.0, 1.0, n))
    t = np.cumsum(dt)
    # body rates: a few sinusoids
    gyr = np.column_stack([0.8 * np.sin(0.7 * t), 0.6 * np.sin(1.1 * t + 1.0), 0.5 * np.cos(0.4 * t)])
    q = np.empty((n, 4))
    q[0] = quat.normalize([0.95, 0.2, -0.1, 0.05])
    for i in range(1, n):
        q[i] = quat.normalize(quat.multiply(q[i - 1], quat.from_rotvec(gyr[i] * dt[i])))
    acc = quat.rotate(quat.conjugate(q), np.array([0.0, 0.0, G])) + 0.05 * rng.standard_normal((n, 3))
    gyr = gyr + 0.002 * rng.standard_normal((n, 3))
    return acc, gyr, dt, q


def heading_free_angle_deg(q_true: np.ndarray, q_est: np.ndarray) -> np.ndarray:
    return np.degrees(quat.inclination_error(q_true, q_est))


# ---------------------------------------------------------------------------------------------------
# interface conformance
# ---------------------------------------------------------------------------------------------------
@pytest.mark.parametrize("name", NAMES)
def test_registry(name: str) -> None:
    cls = estimator_class(name)
    assert cls.name == name
    assert {MadgwickEstimator, MahonyEstimator, VqfEstimator} >= {cls}
    for spec in cls.PARAMS:
        assert spec.validate(spec.default) == spec.default
        # VQF has no setter for biasClip; the front end is set up at the first sample; VQF's σ model tracks its
        # state from the first sample
        assert spec.runtime or spec.name in ("bias_clip", "gyro_bias_estimation", "bias_sigma_init",
                                             "mag_calibration", "mag_hard_iron_sd", "mag_soft_iron_model",
                                             "sigma_model")


@pytest.mark.parametrize("name", NAMES)
def test_output_finite_unit(name: str) -> None:
    acc, gyr, dt, _ = synthetic(1500)
    # degenerate rows: zero acc, non-finite acc and gyr, zero, negative and non-finite dt, huge values
    acc[100] = 0.0
    acc[200] = [np.nan, 1.0, 2.0]
    acc[201] = [np.inf, 0.0, 0.0]
    gyr[300] = [np.nan, 0.0, 0.0]
    gyr[301] = [-np.inf, 0.0, 0.0]
    dt[400] = 0.0
    dt[401] = -0.01
    dt[402] = np.nan
    acc[500] = [1e200, 1e200, 0.0]
    gyr[600] = [1e6, 0.0, 0.0]
    est = create(name)
    q = est.update_batch(acc, gyr, dt)
    assert q.shape == (len(acc), 4)
    assert np.isfinite(q).all()
    np.testing.assert_allclose(np.linalg.norm(q, axis=1), 1.0, atol=1e-9)


@pytest.mark.parametrize("name", NAMES)
def test_batch_equals_stream(name: str) -> None:
    acc, gyr, dt, _ = synthetic(3000, seed=1)
    acc[50] = 0.0  # a gyro-only step on the way
    batch = create(name).update_batch(acc, gyr, dt)
    est = create(name)
    stream = np.array([est.update(a, g, float(h)) for a, g, h in zip(acc, gyr, dt, strict=True)])
    np.testing.assert_allclose(stream, batch, atol=1e-12, rtol=0)
    # batches continue from the state left by earlier calls
    est = create(name)
    parts = [est.update_batch(acc[i : i + 700], gyr[i : i + 700], dt[i : i + 700]) for i in range(0, 3000, 700)]
    np.testing.assert_allclose(np.concatenate(parts), batch, atol=1e-12, rtol=0)


@pytest.mark.parametrize("name", NAMES)
def test_reset(name: str) -> None:
    acc, gyr, dt, _ = synthetic(800, seed=2)
    est = create(name)
    first = est.update_batch(acc, gyr, dt)
    est.update_batch(acc[::-1], -gyr[::-1], dt)  # move the state somewhere else
    est.reset()
    np.testing.assert_array_equal(est.update_batch(acc, gyr, dt), first)


@pytest.mark.parametrize("name", NAMES)
def test_empty_batch(name: str) -> None:
    est = create(name)
    assert est.update_batch(np.empty((0, 3)), np.empty((0, 3)), np.empty(0)).shape == (0, 4)
    q = est.update([0.0, 0.0, G], [0.0, 0.0, 0.0], 0.01)
    assert q.shape == (4,)


@pytest.mark.parametrize("name", NAMES)
def test_unknown_param_rejected(name: str) -> None:
    with pytest.raises(ValueError, match="unknown parameter"):
        create(name, gain=0.1)
    est = create(name)
    with pytest.raises(KeyError):
        est.set_params(gain=0.1)


@pytest.mark.parametrize("name", NAMES)
def test_runtime_params(name: str) -> None:
    key, good, bad = RUNTIME_CHANGE[name]
    acc, gyr, dt, _ = synthetic(1200, seed=3)
    a = create(name)
    b = create(name)
    a.update_batch(acc[:600], gyr[:600], dt[:600])
    b.update_batch(acc[:600], gyr[:600], dt[:600])
    with pytest.raises(ValueError):
        b.set_params(**{key: bad})
    with pytest.raises(ValueError):
        b.set_params(**{key: "fast"})
    assert b.params[key] == b.param_spec(key).default  # rejected values leave the parameter alone
    b.set_params(**{key: good})
    assert b.params[key] == good
    qa = a.update_batch(acc[600:], gyr[600:], dt[600:])
    qb = b.update_batch(acc[600:], gyr[600:], dt[600:])
    assert np.isfinite(qb).all()
    assert np.abs(qa - qb).max() > 1e-6  # the new value takes effect without a reset
    # the value given at construction is the same as one set before the first sample
    c = create(name, **{key: good})
    d = create(name)
    d.set_params(**{key: good})
    np.testing.assert_array_equal(c.update_batch(acc, gyr, dt), d.update_batch(acc, gyr, dt))


def test_vqf_bool_params() -> None:
    acc, gyr, dt, _ = synthetic(1000, seed=4)
    est = create("vqf", motion_bias_est=False, rest_bias_est=False)
    q = est.update_batch(acc, gyr, dt)
    assert np.isfinite(q).all()
    np.testing.assert_array_equal(est.bias, 0.0)  # no bias estimation at all
    with pytest.raises(ValueError):
        est.set_params(rest_bias_est=1)
    est.set_params(rest_bias_est=True, motion_bias_est=True)
    est.update_batch(acc, gyr, dt)
    assert np.abs(est.bias).max() > 0.0


def test_defaults() -> None:
    magcal = {"mag_calibration": True, "mag_hard_iron_sd": 5e-5, "mag_soft_iron_model": "full"}
    front_end = {**magcal, "gyro_bias_estimation": False, "bias_clip": 8.0, "bias_sigma_init": 3.0}
    assert MadgwickEstimator().params == {"beta": DEFAULT_BETA, "beta_marg": 0.041, **front_end} == {
        "beta": 0.033, "beta_marg": 0.041, **front_end}
    assert MahonyEstimator().params == {"kp": DEFAULT_KP, "ki": DEFAULT_KI, **front_end} == {
        "kp": 1.0, "ki": 0.3, **front_end}
    from vqf import VQF

    p = VQF(0.01).params
    assert VqfEstimator().params == {
        "tau_acc": p["tauAcc"],
        "motion_bias_est": p["motionBiasEstEnabled"],
        "rest_bias_est": p["restBiasEstEnabled"],
        "bias_clip": p["biasClip"],
        "tau_mag": p["tauMag"],
        "mag_dist_rejection": p["magDistRejectionEnabled"],
        "sigma_model": "constant",
        **magcal,
    }


@pytest.mark.parametrize("name", NAMES)
def test_config_yaml_lists_every_param_with_its_default(name: str) -> None:
    yaml = pytest.importorskip("yaml")
    path = Path(__file__).resolve().parents[1] / "config" / f"{name}.yaml"
    params = yaml.safe_load(path.read_text())["/**"]["ros__parameters"]
    assert params == {p.name: p.default for p in estimator_class(name).PARAMS}


# ---------------------------------------------------------------------------------------------------
# initialisation, frame convention, dt handling
# ---------------------------------------------------------------------------------------------------
@pytest.mark.parametrize("name", ("madgwick", "mahony"))
def test_initialised_from_first_usable_accelerometer(name: str) -> None:
    est = create(name)
    np.testing.assert_array_equal(est.update([0.0, 0.0, 0.0], [0.1, 0.0, 0.0], 0.01), quat.IDENTITY)
    np.testing.assert_array_equal(est.update([np.nan, 0.0, 0.0], [0.1, 0.0, 0.0], 0.01), quat.IDENTITY)
    a = np.array([1.0, -2.0, 9.0])
    np.testing.assert_allclose(est.update(a, [0.3, 0.2, 0.1], 0.01), quat.from_accelerometer(a), atol=1e-15)


@pytest.mark.parametrize("name", NAMES)
def test_level_at_rest_is_identity(name: str) -> None:
    n = 500
    q = create(name).update_batch(np.tile([0.0, 0.0, G], (n, 1)), np.zeros((n, 3)), np.full(n, 0.01))
    np.testing.assert_allclose(q, np.tile(quat.IDENTITY, (n, 1)), atol=1e-9)


@pytest.mark.parametrize("name", NAMES)
def test_tilted_at_rest_converges(name: str) -> None:
    """Start level, then hold a known tilt with no rotation measured: the accelerometer pulls it over."""
    q_true = quat.normalize(
        quat.multiply(quat.from_rotvec([np.radians(30.0), 0, 0]), quat.from_rotvec([0, np.radians(-20.0), 0]))
    )
    acc_tilt = quat.rotate(quat.conjugate(q_true), [0.0, 0.0, G])
    rate, secs = 100.0, 60.0
    n = int(rate * secs)
    acc = np.tile(acc_tilt, (n, 1))
    acc[:10] = [0.0, 0.0, G]
    est = create(name)
    q = est.update_batch(acc, np.zeros((n, 3)), np.full(n, 1.0 / rate))
    err = heading_free_angle_deg(np.tile(q_true, (n, 1)), q)
    assert err[9] == pytest.approx(np.degrees(quat.inclination_error(q_true, quat.IDENTITY)), abs=0.5)
    assert err[-1] < 0.5
    # the estimate maps the measured specific force onto world +z
    np.testing.assert_allclose(quat.rotate(q[-1], acc_tilt / G), [0, 0, 1], atol=0.01)


@pytest.mark.parametrize("name", NAMES)
def test_tracks_rotation_with_jittered_dt(name: str) -> None:
    """Gyro in the sensor frame, q sensor → world: tracking a known motion keeps the error small."""
    acc, gyr, dt, q_true = synthetic(6000, seed=5)
    q = create(name).update_batch(acc, gyr, dt)
    err = heading_free_angle_deg(q_true, q)
    assert np.sqrt(np.mean(err[500:] ** 2)) < 1.5


@pytest.mark.parametrize("name", NAMES)
def test_heading_integrates_true_dt(name: str) -> None:
    """Level, turning about z at a constant rate, with irregular dt: heading = rate · Σdt."""
    rate_z = 0.5  # rad/s
    n = 1000
    dt = np.where(np.arange(n) % 2 == 0, 0.004, 0.016)  # first dt = 4 ms sets VQF's Ts
    acc = np.tile([0.0, 0.0, G], (n, 1))
    gyr = np.tile([0.0, 0.0, rate_z], (n, 1))
    q = create(name).update_batch(acc, gyr, dt)
    heading = 2.0 * np.arctan2(q[-1, 3], q[-1, 0])
    expected = rate_z * dt[1:].sum()  # the first sample only initialises (VQF integrates it too)
    if name == "vqf":
        expected = rate_z * dt.sum()
    diff = (heading - expected + np.pi) % (2 * np.pi) - np.pi
    assert abs(diff) < np.radians(0.5)


def test_mahony_estimates_gyro_bias() -> None:
    n, rate = 12000, 100.0
    bias = np.array([0.02, -0.015, 0.0])
    est = MahonyEstimator()
    est.update_batch(np.tile([0.0, 0.0, G], (n, 1)), np.tile(bias, (n, 1)), np.full(n, 1.0 / rate))
    np.testing.assert_allclose(est.bias[:2], bias[:2], atol=1e-4)


@pytest.mark.parametrize("name", ("madgwick", "mahony"))
def test_gyro_bias_front_end_removes_a_turn_on_bias(name: str) -> None:
    """Tilted rest with a (3, 3, 0) °/s gyro bias: the filter alone tilts away (Mahony with its own
    integral term off); with the front end it stays within 1°, and the bias shows in the diagnostics."""
    n, rate = 100 * 30, 100.0
    q_true = quat.from_rotvec([np.radians(20.0), 0.0, 0.0])
    acc = np.tile(quat.rotate(quat.conjugate(q_true), [0.0, 0.0, G]), (n, 1))
    gyr = np.tile(np.radians([3.0, 3.0, 0.0]), (n, 1))
    dt = np.full(n, 1.0 / rate)
    extra = {"ki": 0.0} if name == "mahony" else {}
    plain = create(name, **extra)
    fe = create(name, gyro_bias_estimation=True, **extra)
    err_plain = heading_free_angle_deg(q_true, plain.update_batch(acc, gyr, dt)[-500:]).max()
    q_fe = fe.update_batch(acc, gyr, dt)
    err_fe = heading_free_angle_deg(q_true, q_fe[-500:]).max()
    assert err_fe < 1.0 and err_plain > 3.0, (err_fe, err_plain)
    shown = [float(v) for v in fe.diagnostics()["gyro bias estimate (deg/s)"].split(",")]
    np.testing.assert_allclose(shown, [3.0, 3.0, 0.0], atol=0.3)
    # per sample equals batch
    one = create(name, gyro_bias_estimation=True, **extra)
    q_one = np.array([one.update(acc[i], gyr[i], dt[i]) for i in range(600)])
    np.testing.assert_allclose(q_one, q_fe[:600], atol=1e-9)


# ---------------------------------------------------------------------------------------------------
# cross-checks against the reference implementations (ahrs, vqf) on a real BROAD trial
# ---------------------------------------------------------------------------------------------------
@pytest.fixture(scope="module")
def broad_trial():
    from riann_ros.datasets.broad import broad_files, find_broad_dir, read_broad

    d = find_broad_dir()
    if d is None:
        pytest.skip("BROAD not found (set RIANN_BROAD_DIR or put it in ../shared/datasets/broad)")
    files = broad_files(d)
    pick = [f for f in files if f.name.startswith("15_")] or files
    return read_broad(pick[0])


def _sign_aligned(ref: np.ndarray, ours: np.ndarray) -> np.ndarray:
    return ref * np.where(np.sum(ref * ours, axis=1) < 0.0, -1.0, 1.0)[:, None]


@pytest.mark.broad
@pytest.mark.slow
@pytest.mark.parametrize("name", ("madgwick", "mahony"))
def test_matches_ahrs_whole_trial(name: str, broad_trial) -> None:
    """ahrs batch API over the whole trial, same gains, dt and initial quaternion: equal within 1e-6."""
    ahrs = pytest.importorskip("ahrs")
    rec = broad_trial
    rate = float(rec.meta["sampling_rate"])
    acc, gyr = rec.acc, rec.gyr
    assert (np.linalg.norm(gyr, axis=1) > 0).all()  # ahrs skips zero-gyro samples entirely; we do not
    q0 = quat.from_accelerometer(acc[0])
    dt = np.full(len(acc), 1.0 / rate)
    if name == "madgwick":
        ref = ahrs.filters.Madgwick(gyr=gyr, acc=acc, frequency=rate, q0=q0, gain=0.033).Q
        ours = MadgwickEstimator(beta=0.033).update_batch(acc, gyr, dt)
    else:
        ref = ahrs.filters.Mahony(gyr=gyr, acc=acc, frequency=rate, q0=q0, k_P=1.0, k_I=0.3).Q
        ours = MahonyEstimator(kp=1.0, ki=0.3).update_batch(acc, gyr, dt)
    # speed against ahrs is a benchmark (bench/bench_filters.py, BENCHMARKS.md), not a timed test
    assert len(ours) == len(acc) > 40000
    np.testing.assert_allclose(ours, _sign_aligned(ref, ours), atol=1e-6, rtol=0)


@pytest.mark.broad
@pytest.mark.parametrize("name", ("madgwick", "mahony"))
def test_matches_ahrs_step_api_jittered_dt(name: str, broad_trial) -> None:
    """ahrs per-sample ``updateIMU(q, gyr, acc, dt)`` with a different dt every sample, other gains."""
    ahrs = pytest.importorskip("ahrs")
    rec = broad_trial
    n = 5000
    acc, gyr = rec.acc[:n], rec.gyr[:n]
    dt = (1.0 / 285.7) * (1.0 + 0.3 * np.sin(np.arange(n)))
    if name == "madgwick":
        ref_filter = ahrs.filters.Madgwick(gain=0.12)
        ours = MadgwickEstimator(beta=0.12).update_batch(acc, gyr, dt)
    else:
        ref_filter = ahrs.filters.Mahony(k_P=0.74, k_I=0.0012)
        ours = MahonyEstimator(kp=0.74, ki=0.0012).update_batch(acc, gyr, dt)
    ref = np.empty((n, 4))
    ref[0] = quat.from_accelerometer(acc[0])
    for i in range(1, n):
        ref[i] = ref_filter.updateIMU(ref[i - 1], gyr[i], acc[i], dt=float(dt[i]))
    np.testing.assert_allclose(ours, _sign_aligned(ref, ours), atol=1e-6, rtol=0)


@pytest.mark.broad
def test_vqf_matches_vqf_package(broad_trial) -> None:
    """With a constant dt the wrapper is exactly ``VQF(dt).updateBatch(gyr, acc)['quat6D']``."""
    from vqf import VQF

    rec = broad_trial
    ts = 1.0 / float(rec.meta["sampling_rate"])
    ref = VQF(ts, tauAcc=2.0).updateBatch(np.ascontiguousarray(rec.gyr), np.ascontiguousarray(rec.acc))["quat6D"]
    ours = VqfEstimator(tau_acc=2.0).update_batch(rec.acc, rec.gyr, np.full(len(rec.acc), ts))
    np.testing.assert_allclose(ours, ref, atol=1e-12, rtol=0)


@pytest.mark.broad
def test_rmse_sanity_on_broad(broad_trial) -> None:

    rec = broad_trial
    dt = np.full(len(rec.acc), 1.0 / float(rec.meta["sampling_rate"]))
    limits = {"vqf": 3.0, "madgwick": 6.0}  # measured on trial 15: VQF 0.47°, Madgwick (β = 0.033) 3.3°
    for name, limit in limits.items():
        q = create(name).update_batch(rec.acc, rec.gyr, dt)
        assert rmse(rec, q) < limit, name


def test_vqf_bias_clip_lets_a_larger_turn_on_bias_be_learned() -> None:
    n = 3000  # 30 s at rest, level, with a turn-on bias of (3, -3, 1) deg/s
    acc = np.tile([0.0, 0.0, G], (n, 1))
    gyr = np.tile(np.radians([3.0, -3.0, 1.0]), (n, 1))
    default, wide = create("vqf"), create("vqf", bias_clip=8.0)
    default.update_batch(acc, gyr, np.full(n, 0.01))
    q = wide.update_batch(acc, gyr, np.full(n, 0.01))
    assert np.abs(np.degrees(default.bias)).max() <= 2.0 + 1e-9  # clipped, rest never detected
    np.testing.assert_allclose(np.degrees(wide.bias), [3.0, -3.0, 1.0], atol=0.2)
    assert np.degrees(quat.inclination_error(quat.IDENTITY, q[-1])) < 0.5
