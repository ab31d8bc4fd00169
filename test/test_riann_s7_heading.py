"""riann_ros/estimators/riann/s7_heading.py: a heading that starts at zero and follows the gyro, the field moving the
heading only (the plain-float form against the vectorised reference, on random blocks)."""

from __future__ import annotations

import math

import numpy as np
import pytest
from helpers_mag import gravity_angle, heading_change_deg, moving
from helpers_riann import AT_REST, G, field_rows
from hypothesis import given, settings
from hypothesis import strategies as st

from riann_ros.estimators import create
from riann_ros.estimators.riann import RiannEstimator
from riann_ros.estimators.riann.s7_heading import Heading
from riann_ros.estimators.riann.stage import SMALL_BLOCK, CarryBlock, HandoverBlock, HeadingIn, Samples
from riann_ros.evaluation.scoring import roll_pitch_deg
from riann_ros.magcal.frontend import FrontEndConfig, LatencySettings, MagFrontEnd
from riann_ros.rotations import from_rotvec, normalized


def _heading_in(qc: list, delta: list, mag: list, bridges: dict[int, float], sd: list[float]) -> HeadingIn:
    """What stage 7 reads: samples (10 ms steps, fields), the gyro increments and the handed-over attitudes."""
    n = len(qc)
    hand = HandoverBlock(qc, sd, [0.0] * n, bridges)
    return HeadingIn(Samples.of([AT_REST] * n, [0.01] * n, mag), CarryBlock(qc, delta), hand)


def _random_block(n: int, seed: int, first_field: int, hole: int) -> tuple[list, list, list, dict[int, float], list]:
    rng = np.random.default_rng(seed)
    qc = [normalized(tuple(q)) for q in (np.array([1.0, 0.1, 0, 0]) + 0.05 * rng.normal(size=(n, 4))).tolist()]
    delta = [from_rotvec(*v) for v in (0.02 * rng.normal(size=(n, 3))).tolist()]
    mag = [None] * first_field + field_rows(n - first_field)
    sd = [float(v) for v in np.where(np.arange(n) >= hole, rng.uniform(0.0, 5.0, n), 0.0)]
    return qc, delta, mag, ({hole: 5.0} if hole < n else {}), sd


@settings(max_examples=40, deadline=None)
@given(seed=st.integers(0, 2**32 - 1), n=st.integers(SMALL_BLOCK + 1, 80), first=st.integers(0, 90),
       hole=st.integers(0, 90))
def test_the_plain_float_form_equals_the_vectorised_reference(seed, n, first, hole):
    """A block of more than SMALL_BLOCK samples (the reference) equals its samples one at a time (the plain-float
    path), attitudes, gains and dips, with the first field and a hole anywhere."""
    qc, delta, mag, bridges, sd = _random_block(n, seed, min(first, n), hole)
    vec = Heading(9.0, True, _front()).run(_heading_in(qc, delta, mag, bridges, sd))
    one = Heading(9.0, True, _front())
    parts = [one.run(_heading_in([qc[k]], [delta[k]], [mag[k]], {0: 5.0} if k in bridges else {}, [sd[k]]))
             for k in range(n)]
    assert np.abs(np.vstack([p.q for p in parts]) - vec.q).max() < 1e-9
    assert np.abs(np.array([p.gain[0] for p in parts]) - vec.gain).max() < 1e-12
    assert [p.dip_rad[0] for p in parts] == pytest.approx(vec.dip_rad, abs=1e-12)
    assert one.mag.started == (first < n)


def test_heading_starts_at_zero_and_follows_the_gyro():
    n = 200 * 10
    acc = np.tile([0.0, 0.0, G], (n, 1))
    rate = math.radians(10.0)
    gyr = np.tile([0.0, 0.0, rate], (n, 1))
    est = RiannEstimator(gyro_bias_estimation=False)
    q = est.update_batch(acc, gyr, np.full(n, 0.005))
    yaw = 2 * np.arctan2(q[:, 3], q[:, 0])
    assert abs(yaw[0]) < 1e-6
    expected = np.remainder(rate * 0.005 * np.arange(n) + np.pi, 2 * np.pi) - np.pi
    err = np.remainder(yaw - expected + np.pi, 2 * np.pi) - np.pi
    assert np.abs(err).max() < math.radians(0.5)


@pytest.mark.parametrize("roll_deg", [20.0, 120.0, -75.0])
def test_tilted_sensor_at_rest_gets_the_network_roll_and_heading_zero(roll_deg):
    """A sensor at rest, rolled: the output's heading (ZYX yaw) starts at 0 and stays there (not near 180°), its roll
    is the tilt."""
    n = 400
    r = math.radians(roll_deg)
    acc = np.tile([0.0, G * math.sin(r), G * math.cos(r)], (n, 1))
    q = RiannEstimator().update_batch(acc, np.zeros((n, 3)), np.full(n, 0.005))
    w, x, y, z = q.T
    yaw = np.degrees(np.arctan2(2 * (w * z + x * y), 1 - 2 * (y * y + z * z)))
    roll = roll_pitch_deg(q)[:, 0]
    # not 180°: the heading starts at zero; the first output's inclination error (a degree or two, corrected
    # afterwards about horizontal axes) leaves a ZYX yaw of that order at large tilts
    assert np.abs(yaw).max() < 2.0
    assert abs(roll[-1] - roll_deg) < 2.0


def test_riann_9d_inclination_equals_6d_synthetic() -> None:
    rec = moving(duration=15.0, seed=9)
    assert rec.mag is not None
    mag = rec.mag.copy()
    mag[::3] = np.nan
    mag[500:700] = np.nan
    mag[900:1000] += np.array([50e-6, 0.0, 0.0])  # a disturbance as well
    dt = rec.dt
    q6 = create("riann").update_batch(rec.acc, rec.gyr, dt)
    q9 = create("riann").update_batch(rec.acc, rec.gyr, dt, mag)
    assert gravity_angle(q6, q9).max() < 1e-6
    assert heading_change_deg(q6, q9).max() > 1.0  # the heading did change


@pytest.mark.slow
@pytest.mark.broad
def test_riann_9d_inclination_equals_6d_broad(broad_trial) -> None:
    rec = broad_trial("01")
    assert rec.mag is not None
    rec = rec.slice(0, int(30.0 * rec.rate_hz))
    norms = np.linalg.norm(rec.mag, axis=1)
    assert 20e-6 < float(np.median(norms)) < 70e-6  # tesla
    q6 = create("riann").update_batch(rec.acc, rec.gyr, rec.dt)
    est = create("riann")
    q9 = est.update_batch(rec.acc, rec.gyr, rec.dt, rec.mag)
    assert gravity_angle(q6, q9).max() < 1e-6
    assert est.heading_observed()


def _front() -> MagFrontEnd:
    """RIANN's front end without the online calibration (the field as given, its latency estimated)."""
    return MagFrontEnd(FrontEndConfig(calibrate=False), latency=LatencySettings(0.0, estimate=True, compensate=True))
