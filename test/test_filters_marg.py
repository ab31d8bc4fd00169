"""The MARG (9D, magnetometer) forms of Madgwick and Mahony: cross-checks against ahrs, frames, heading,
streaming = batch, the 6D fallback for samples without a field, degenerate input."""

from __future__ import annotations

import math

import numpy as np
import pytest

from riann_ros import quaternion as quat
from riann_ros.estimators import create
from riann_ros.estimators.bias import GyroBiasFrontEnd
from riann_ros.estimators.common import initial_attitude, initial_attitude_marg
from riann_ros.estimators.madgwick import C_NWU_TO_ENU, DEFAULT_BETA, DEFAULT_BETA_MARG
from riann_ros.estimators.mahony import DEFAULT_KI, DEFAULT_KP

NAMES = ("madgwick", "mahony")
G = 9.81
#: a plausible geomagnetic field in magnetic ENU (tesla): horizontal along +y (magnetic north), dip ~65° down
FIELD_ENU = 50e-6 * np.array([0.0, math.cos(math.radians(65.0)), -math.sin(math.radians(65.0))])
#: ahrs' earth frame as sensor → ENU: q_ENU = C ⊗ q_ahrs (Madgwick: NWU, Mahony: ENU already)
AHRS_FRAME_TO_ENU = {"madgwick": np.asarray(C_NWU_TO_ENU), "mahony": np.array([1.0, 0.0, 0.0, 0.0])}


def rot_z(angle: float) -> np.ndarray:
    return np.array([math.cos(0.5 * angle), 0.0, 0.0, math.sin(0.5 * angle)])


def synthetic9(
    n: int = 3000, seed: int = 0, rate: float = 100.0, noise: bool = True
) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Smooth random motion with a constant world field: acc, gyr, mag (tesla), dt, true attitude (ENU)."""
    rng = np.random.default_rng(seed)
    dt = (1.0 / rate) * (1.0 + 0.2 * rng.uniform(-1.0, 1.0, n))
    t = np.cumsum(dt)
    ph = rng.uniform(0.0, 2.0 * np.pi, 3)
    gyr = np.column_stack([0.9 * np.sin(0.7 * t + ph[0]), 0.7 * np.sin(1.1 * t + ph[1]), 1.2 * np.cos(0.4 * t + ph[2])])
    q = np.empty((n, 4))
    q[0] = quat.normalize(rng.standard_normal(4))
    for i in range(1, n):
        q[i] = quat.normalize(quat.multiply(q[i - 1], quat.from_rotvec(gyr[i] * dt[i])))
    acc = quat.rotate(quat.conjugate(q), np.array([0.0, 0.0, G]))
    mag = quat.rotate(quat.conjugate(q), FIELD_ENU)
    if noise:
        acc += 0.05 * rng.standard_normal((n, 3))
        mag += 0.5e-6 * rng.standard_normal((n, 3))
        gyr = gyr + 0.01 * rng.standard_normal((n, 3)) + np.array([0.01, -0.02, 0.015])  # noise + a bias
    return acc, gyr, mag, dt, q


def ahrs_marg(name: str, acc, gyr, mag, dt, q0_enu, **gains) -> np.ndarray:
    """ahrs ``updateMARG`` sample by sample from ``q0_enu`` (converted into ahrs' frame); outputs in ENU."""
    filters = pytest.importorskip("ahrs.filters")
    c = AHRS_FRAME_TO_ENU[name]
    if name == "madgwick":
        f = filters.Madgwick(gain=gains.get("beta_marg", DEFAULT_BETA_MARG))
    else:
        f = filters.Mahony(k_P=gains.get("kp", DEFAULT_KP), k_I=gains.get("ki", DEFAULT_KI))
    q = quat.multiply(quat.conjugate(c), np.asarray(q0_enu, dtype=float))
    out = np.empty((len(acc), 4))
    out[0] = q
    for t in range(1, len(acc)):
        q = f.updateMARG(q, gyr[t], acc[t], mag[t], dt=float(dt[t]))
        out[t] = q
    return quat.multiply(c, out)


def sign_aligned(ref: np.ndarray, q: np.ndarray) -> np.ndarray:
    """``q`` with each row's sign chosen to match ``ref`` (q and −q are the same attitude)."""
    s = np.where(np.sum(ref * q, axis=1) < 0.0, -1.0, 1.0)
    return q * s[:, None]


def max_diff_to_ahrs(name: str, acc, gyr, mag, dt, **params) -> float:
    est = create(name, mag_calibration=False, **params)  # the filter's equations: ahrs has no field calibration
    ours = est.update_batch(acc, gyr, dt, mag)
    ref = ahrs_marg(name, acc, gyr, mag, dt, ours[0], **params)
    return float(np.abs(sign_aligned(ours, ref) - ours).max())


# ---------------------------------------------------------------------------------------------------
# cross-checks against ahrs 0.4.0 updateMARG
# ---------------------------------------------------------------------------------------------------
@pytest.mark.parametrize("name", NAMES)
def test_matches_ahrs_synthetic(name: str) -> None:
    acc, gyr, mag, dt, _ = synthetic9(3000, seed=4)
    assert (np.abs(gyr).sum(axis=1) > 0).all()  # ahrs skips samples with an exactly zero gyro
    assert max_diff_to_ahrs(name, acc, gyr, mag, dt) < 1e-6


@pytest.mark.parametrize(("name", "params"), [("madgwick", {"beta_marg": 0.2}), ("mahony", {"kp": 2.0, "ki": 0.05})])
def test_matches_ahrs_synthetic_other_gains(name: str, params: dict) -> None:
    acc, gyr, mag, dt, _ = synthetic9(2000, seed=5)
    assert max_diff_to_ahrs(name, acc, gyr, mag, dt, **params) < 1e-6


@pytest.mark.broad
@pytest.mark.slow
@pytest.mark.parametrize("name", NAMES)
def test_matches_ahrs_broad(name: str, broad_trial) -> None:
    rec = broad_trial("01")  # no exactly-zero gyro rows (ahrs skips those, we integrate them)
    assert rec.mag is not None
    assert (np.abs(rec.gyr).sum(axis=1) > 0).all()
    assert max_diff_to_ahrs(name, rec.acc, rec.gyr, rec.mag, rec.dt) < 1e-6


# ---------------------------------------------------------------------------------------------------
# plain references: the documented equations with numpy vectors, one sample at a time; the fast loops
# (Python floats in local variables) must give the same numbers
# ---------------------------------------------------------------------------------------------------
def _unit_or_none(v: np.ndarray) -> np.ndarray | None:
    n = float(np.linalg.norm(v))
    return v / n if 0.0 < n < math.inf else None


def _integrate(q: np.ndarray, q_dot: np.ndarray, h: float) -> np.ndarray:
    """``normalise(q + q̇ h)``, the previous ``q`` where that is not a finite unit quaternion."""
    nxt = _unit_or_none(q + q_dot * h)
    return q if nxt is None else nxt


def _start(a: np.ndarray, m: np.ndarray | None) -> np.ndarray | None:
    """The initial attitude (sensor → ENU) from the first usable accelerometer sample, heading from its field."""
    if m is None:
        q = initial_attitude(*a)
    else:
        q = initial_attitude_marg(*a, *m)
    return None if q is None else np.array(q)


def _rows(acc, gyr, mag, dt):
    """The samples as the estimators see them: non-finite acc/gyr/mag rows zero, bad dt zero."""
    acc, gyr, dt = (np.nan_to_num(np.where(np.isfinite(x).all(axis=-1, keepdims=True), x, 0.0))
                    for x in (np.asarray(acc, float), np.asarray(gyr, float), np.asarray(dt, float)[:, None]))
    dt = np.where(dt[:, 0] > 0.0, dt[:, 0], 0.0)
    if mag is not None:
        mag = np.asarray(mag, float)
        mag = np.where(np.isfinite(mag).all(axis=1, keepdims=True), mag, 0.0)
    return acc, gyr, mag, dt


def mahony_reference(acc, gyr, mag, dt, kp: float = DEFAULT_KP, ki: float = DEFAULT_KI) -> np.ndarray:
    """Mahony et al. 2008 as in the module docstring: e = â × R(q)ᵀe_z (+ m̂ × v_m with a field),
    b ← b − k_I e dt, q ← normalise(q + ½ q ⊗ [0, ω − b + k_P e] dt); bias frozen on a zero accelerometer."""
    acc, gyr, mag, dt = _rows(acc, gyr, mag, dt)
    ez = np.array([0.0, 0.0, 1.0])
    q: np.ndarray | None = None
    b = np.zeros(3)
    out = []
    for k in range(len(acc)):
        if q is None:
            q = _start(acc[k], None if mag is None else mag[k])
            out.append(quat.IDENTITY if q is None else q)
            continue
        w = gyr[k] - b
        a = _unit_or_none(acc[k])
        if a is not None:
            e = np.cross(a, quat.rotate(quat.conjugate(q), ez))
            m = None if mag is None else _unit_or_none(mag[k])
            if m is not None:
                hw = quat.rotate(q, m)
                v_m = _unit_or_none(quat.rotate(quat.conjugate(q), [0.0, math.hypot(hw[0], hw[1]), hw[2]]))
                if v_m is not None:
                    e = e + np.cross(m, v_m)
            b = b - ki * dt[k] * e
            w = gyr[k] - b + kp * e
        q = _integrate(q, 0.5 * quat.multiply(q, np.r_[0.0, w]), dt[k])
        out.append(q)
    return np.array(out)


def _madgwick_gradient(q: np.ndarray, a: np.ndarray, m: np.ndarray | None) -> np.ndarray:
    """Jᵀ f of Madgwick 2010 (eqs. 25-26 and 29-34): gravity rows, and the field rows with b = (b_x, 0, b_z)."""
    q0, q1, q2, q3 = q
    f = [2 * (q1 * q3 - q0 * q2) - a[0], 2 * (q0 * q1 + q2 * q3) - a[1], 2 * (0.5 - q1 * q1 - q2 * q2) - a[2]]
    jac = [[-2 * q2, 2 * q3, -2 * q0, 2 * q1], [2 * q1, 2 * q0, 2 * q3, 2 * q2], [0.0, -4 * q1, -4 * q2, 0.0]]
    if m is not None:
        hw = quat.rotate(q, m)
        bx, bz = math.hypot(hw[0], hw[1]), hw[2]
        f += [2 * bx * (0.5 - q2 * q2 - q3 * q3) + 2 * bz * (q1 * q3 - q0 * q2) - m[0],
              2 * bx * (q1 * q2 - q0 * q3) + 2 * bz * (q0 * q1 + q2 * q3) - m[1],
              2 * bx * (q0 * q2 + q1 * q3) + 2 * bz * (0.5 - q1 * q1 - q2 * q2) - m[2]]
        jac += [[-2 * bz * q2, 2 * bz * q3, -4 * bx * q2 - 2 * bz * q0, -4 * bx * q3 + 2 * bz * q1],
                [-2 * bx * q3 + 2 * bz * q1, 2 * bx * q2 + 2 * bz * q0, 2 * bx * q1 + 2 * bz * q3,
                 -2 * bx * q0 + 2 * bz * q2],
                [2 * bx * q2, 2 * bx * q3 - 4 * bz * q1, 2 * bx * q0 - 4 * bz * q2, 2 * bx * q1]]
    return np.array(jac).T @ np.array(f)


def madgwick_reference(acc, gyr, mag, dt, beta: float = DEFAULT_BETA,
                       beta_marg: float = DEFAULT_BETA_MARG) -> np.ndarray:
    """Madgwick 2010 as in the module docstring: q̇ = ½ q ⊗ [0, ω] − β ∇f/‖∇f‖; with ``mag`` the recursion
    runs in his NWU earth frame (outputs C ⊗ q), with β_marg on samples with a field."""
    acc, gyr, mag, dt = _rows(acc, gyr, mag, dt)
    c = np.asarray(C_NWU_TO_ENU) if mag is not None else quat.IDENTITY
    q: np.ndarray | None = None
    out = []
    for k in range(len(acc)):
        if q is None:
            q0 = _start(acc[k], None if mag is None else mag[k])
            out.append(quat.IDENTITY if q0 is None else q0)
            q = None if q0 is None else quat.multiply(quat.conjugate(c), q0)
            continue
        q_dot = 0.5 * quat.multiply(q, np.r_[0.0, gyr[k]])
        a = _unit_or_none(acc[k])
        if a is not None:
            m = None if mag is None else _unit_or_none(mag[k])
            grad = _madgwick_gradient(q, a, m)
            step = _unit_or_none(grad)
            if step is not None:
                q_dot = q_dot - (beta if m is None else beta_marg) * step
        q = _integrate(q, q_dot, dt[k])
        out.append(quat.multiply(c, q))
    return np.array(out)


REFERENCES = {"madgwick": madgwick_reference, "mahony": mahony_reference}


@pytest.mark.parametrize("name", NAMES)
@pytest.mark.parametrize("case", ["6d", "9d", "mixed", "gains"])
def test_loops_match_the_plain_reference(name: str, case: str) -> None:
    """The fast loops equal the documented equations written plainly (numpy vectors, one sample at a time) on a
    seeded stream: 6D, 9D, 9D with missing-field, zero-acc, bad-gyro and bad-dt rows, and other gains."""
    acc, gyr, mag, dt, _ = synthetic9(2500, seed=11)
    params: dict = {}
    if case == "6d":
        mag = None
    if case in ("mixed", "gains"):
        mag[::7] = np.nan
        mag[3::11] = 0.0
        mag[400:520] = np.nan
        acc[[0, 50, 51]] = 0.0
        acc[60] = np.nan
        gyr[70] = [np.inf, 0.0, 0.0]
        dt[[80, 81, 82]] = [0.0, -0.01, np.nan]
    if case == "gains":
        params = {"beta": 0.2, "beta_marg": 0.3} if name == "madgwick" else {"kp": 2.5, "ki": 0.05}
    ours = create(name, **params).update_batch(acc, gyr, dt, mag)
    ref = REFERENCES[name](acc, gyr, mag, dt, **params)
    np.testing.assert_allclose(ours, ref, atol=1e-12, rtol=0)


# ---------------------------------------------------------------------------------------------------
# interface: streaming = batch, 6D fallback, parameters, front end
# ---------------------------------------------------------------------------------------------------
def mixed_field(n: int, seed: int = 1) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    acc, gyr, mag, dt, _ = synthetic9(n, seed=seed)
    mag[::7] = np.nan  # e.g. a slower magnetometer
    mag[3::11] = 0.0
    mag[500:650] = np.nan
    acc[50] = 0.0
    return acc, gyr, mag, dt


@pytest.mark.parametrize("name", NAMES)
def test_stream_equals_batch(name: str) -> None:
    acc, gyr, mag, dt = mixed_field(2000)
    est = create(name)
    batch = est.update_batch(acc, gyr, dt, mag)
    observed_batch = est.heading_observed()
    est = create(name)
    stream = []
    observed = []
    for a, g, h, m in zip(acc, gyr, dt, mag, strict=True):
        stream.append(est.update(a, g, float(h), m))
        observed.append(est.heading_observed())
    np.testing.assert_allclose(np.array(stream), batch, atol=1e-12, rtol=0)
    assert observed[-1] == observed_batch
    usable = np.isfinite(mag).all(axis=1) & (np.abs(mag).sum(axis=1) > 0) & (np.abs(acc).sum(axis=1) > 0)
    assert observed == usable.tolist()
    # batches continue from the state left by earlier calls (also across mag=None batches)
    est = create(name)
    parts = [
        est.update_batch(acc[i : i + 300], gyr[i : i + 300], dt[i : i + 300], mag[i : i + 300])
        for i in range(0, 2000, 300)
    ]
    np.testing.assert_allclose(np.concatenate(parts), batch, atol=1e-12, rtol=0)


@pytest.mark.parametrize("name", NAMES)
def test_mag_none_is_6d(name: str) -> None:
    acc, gyr, _, dt, _ = synthetic9(1500, seed=2)
    est = create(name)
    q = est.update_batch(acc, gyr, dt, None)
    assert not est.heading_observed()
    # the IMU equations on every sample, in the ENU frame
    np.testing.assert_allclose(q, REFERENCES[name](acc, gyr, None, dt), atol=1e-12, rtol=0)
    np.testing.assert_allclose(create(name).update_batch(acc, gyr, dt), q, atol=1e-15, rtol=0)


@pytest.mark.parametrize("name", NAMES)
def test_no_field_rows_are_6d(name: str) -> None:
    """A mag array without any usable row gives the 6D result. Madgwick's MARG loop runs in his NWU
    earth frame, so its 6D steps there differ from the ENU 6D loop by round-off only (the 6D objective is
    invariant under rotations about world z); Mahony runs the very same arithmetic."""
    acc, gyr, _, dt, _ = synthetic9(3000, seed=3)
    six = create(name).update_batch(acc, gyr, dt)
    mag = np.full_like(acc, np.nan)
    mag[::2] = 0.0
    est = create(name)
    nine = est.update_batch(acc, gyr, dt, mag)
    assert not est.heading_observed()
    assert np.abs(nine - six).max() < 1e-9


@pytest.mark.parametrize("name", NAMES)
def test_marg_differs_from_6d(name: str) -> None:
    acc, gyr, mag, dt, _ = synthetic9(1000, seed=6)
    six = create(name).update_batch(acc, gyr, dt)
    nine = create(name).update_batch(acc, gyr, dt, mag)
    assert np.degrees(quat.heading_error(nine, six)).max() > 1.0


def test_madgwick_beta_marg_only_with_field() -> None:
    acc, gyr, mag, dt, _ = synthetic9(1000, seed=7)
    nan = np.full_like(mag, np.nan)
    base = create("madgwick")
    other_marg = create("madgwick", beta_marg=0.3)
    other_beta = create("madgwick", beta=0.3)
    # without a field only beta matters ...
    np.testing.assert_allclose(
        other_marg.update_batch(acc, gyr, dt, nan), base.update_batch(acc, gyr, dt, nan), atol=1e-15, rtol=0
    )
    # ... with a field in every sample only beta_marg
    for e in (base, other_marg, other_beta):
        e.reset()
    q = base.update_batch(acc, gyr, dt, mag)
    np.testing.assert_allclose(other_beta.update_batch(acc, gyr, dt, mag), q, atol=1e-15, rtol=0)
    assert np.abs(other_marg.update_batch(acc, gyr, dt, mag) - q).max() > 1e-4
    # runtime change
    base.set_params(beta_marg=0.5)
    assert base.params["beta_marg"] == 0.5
    with pytest.raises(ValueError):
        base.set_params(beta_marg=-1.0)
    assert base.param_spec("beta_marg").runtime


@pytest.mark.parametrize("name", NAMES)
def test_front_end_applies_in_9d(name: str) -> None:
    acc, gyr, mag, dt, _ = synthetic9(1500, seed=8)
    gyr = gyr + np.radians([2.0, -1.5, 3.0])
    est = create(name, gyro_bias_estimation=True)
    q = est.update_batch(acc, gyr, dt, mag)
    fe = GyroBiasFrontEnd(float(dt[0]))
    debiased = gyr - fe.update_batch(acc, gyr, dt)
    ref = create(name).update_batch(acc, debiased, dt, mag)
    np.testing.assert_allclose(q, ref, atol=1e-12, rtol=0)
    assert np.abs(q - create(name).update_batch(acc, gyr, dt, mag)).max() > 1e-6


@pytest.mark.parametrize("name", NAMES)
def test_uses_mag_and_mag_shape(name: str) -> None:
    est = create(name)
    assert est.USES_MAG
    assert not est.heading_observed()
    with pytest.raises(ValueError, match="mag"):
        est.update_batch(np.zeros((3, 3)), np.zeros((3, 3)), 0.01, np.zeros((2, 3)))


# ---------------------------------------------------------------------------------------------------
# heading: the field's horizontal part is magnetic north (+y of ENU)
# ---------------------------------------------------------------------------------------------------
def static(q_true: np.ndarray, n: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    acc = np.tile(quat.rotate(quat.conjugate(q_true), [0.0, 0.0, G]), (n, 1))
    mag = np.tile(quat.rotate(quat.conjugate(q_true), FIELD_ENU), (n, 1))
    gyr = np.full((n, 3), 1e-9)  # not exactly zero (irrelevant for us, kept realistic)
    return acc, gyr, mag


@pytest.mark.parametrize("name", NAMES)
@pytest.mark.parametrize("yaw_deg", [-150.0, 40.0, 100.0])
def test_static_heading_converges(name: str, yaw_deg: float) -> None:
    tilt = quat.normalize(quat.from_rotvec(np.radians([20.0, -15.0, 0.0])))
    q_true = quat.multiply(rot_z(math.radians(yaw_deg)), tilt)
    rate = 100.0
    n = int(200 * rate)
    acc, gyr, mag = static(q_true, n)
    dt = np.full(n, 1.0 / rate)
    # the first second without a field: initialised with zero heading, heading not observed
    est = create(name)
    est.update_batch(acc[:100], gyr[:100], dt[:100], np.full((100, 3), np.nan))
    assert not est.heading_observed()
    err0 = float(np.degrees(quat.heading_error(q_true, est.update(acc[100], gyr[100], 0.01, np.full(3, np.nan)))))
    assert err0 > 30.0
    q = est.update_batch(acc[101:], gyr[101:], dt[101:], mag[101:])
    assert est.heading_observed()
    assert np.degrees(quat.heading_error(q_true, q[-1])) < 0.1
    assert np.degrees(quat.inclination_error(q_true, q[-1])) < 0.1
    # the field of the first sample sets the heading at once
    est.reset()
    assert not est.heading_observed()
    q0 = est.update(acc[0], gyr[0], 0.01, mag[0])
    assert est.heading_observed()
    assert np.degrees(quat.total_error(q_true, q0)) < 1e-6


@pytest.mark.parametrize("name", NAMES)
def test_heading_observed_flag(name: str) -> None:
    acc, gyr, mag, dt, _ = synthetic9(200, seed=9)
    est = create(name)
    est.update_batch(acc[:100], gyr[:100], dt[:100], mag[:100])
    assert est.heading_observed()
    est.update(acc[100], gyr[100], 0.01, [np.nan, np.nan, np.nan])
    assert not est.heading_observed()
    est.update(acc[101], gyr[101], 0.01, mag[101])
    assert est.heading_observed()
    est.update([0.0, 0.0, 0.0], gyr[102], 0.01, mag[102])  # zero acc: gyro-only step
    assert not est.heading_observed()
    est.update(acc[103], gyr[103], 0.01, mag[103])
    assert est.heading_observed()
    est.update(acc[104], gyr[104], 0.01)  # mag=None: the 6D step
    assert not est.heading_observed()
    est.update(acc[105], gyr[105], 0.01, mag[105])
    est.update_batch(np.empty((0, 3)), np.empty((0, 3)), np.empty(0), np.empty((0, 3)))  # nothing processed
    assert est.heading_observed()
    est.reset()
    assert not est.heading_observed()


# ---------------------------------------------------------------------------------------------------
# degenerate input
# ---------------------------------------------------------------------------------------------------
@pytest.mark.parametrize("name", NAMES)
def test_degenerate_finite_unit(name: str) -> None:
    acc, gyr, mag, dt, _ = synthetic9(1500, seed=10)
    mag[0] = np.nan  # initialisation without a field
    mag[100] = 0.0
    mag[101] = [np.nan, 1e-5, 0.0]
    mag[102] = [np.inf, 0.0, 0.0]
    mag[103] = [1e200, 1e200, 0.0]
    mag[104] = [0.0, 0.0, 1e-300]
    mag[105] = quat.rotate(quat.conjugate(quat.from_accelerometer(acc[105])), [0.0, 0.0, 1e-5])  # vertical field
    acc[200] = 0.0
    acc[201] = [np.nan, 1.0, 2.0]
    acc[202] = [1e200, 1e200, 0.0]
    gyr[300] = [np.nan, 0.0, 0.0]
    gyr[301] = 0.0
    gyr[302] = [1e6, 0.0, 0.0]
    dt[400] = 0.0
    dt[401] = -0.01
    dt[402] = np.nan
    est = create(name)
    q = est.update_batch(acc, gyr, dt, mag)
    assert q.shape == (len(acc), 4)
    assert np.isfinite(q).all()
    np.testing.assert_allclose(np.linalg.norm(q, axis=1), 1.0, atol=1e-9)
    # all-degenerate streams: identity until a usable accelerometer sample, then finite unit quaternions
    est = create(name)
    z = np.zeros((5, 3))
    q = est.update_batch(z, z, 0.01, np.full((5, 3), np.nan))
    np.testing.assert_allclose(q, np.tile([1.0, 0.0, 0.0, 0.0], (5, 1)), atol=1e-15)
    assert not est.heading_observed()
    q = est.update_batch(np.tile([0.0, 0.0, G], (5, 1)), z, 0.01, z)
    assert np.isfinite(q).all()
    np.testing.assert_allclose(np.linalg.norm(q, axis=1), 1.0, atol=1e-12)
    assert not est.heading_observed()
