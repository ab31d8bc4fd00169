"""riann_ros/magcal/latency.py: the magnetometer's latency estimated online from the gyro, and
compensated."""

from __future__ import annotations

import numpy as np
import pytest
from helpers_mag import IDENTITY_Q, delayed_field, moving

from riann_ros import quaternion as quat
from riann_ros.estimators import create
from riann_ros.magcal.latency import LatencyEstimator
from riann_ros.rotations import from_rotvec


@pytest.mark.parametrize("delay_samples", [0, 2, 4])
def test_latency_estimator_finds_the_field_delay(delay_samples: int) -> None:
    """The reference-free fit recovers a magnetometer latency of 0, 10 and 20 ms from the gyro alone (true
    gyro with noise, no network: the heading stage's LatencyEstimator fed sample by sample). The latency is
    measured against the filters' integration convention (a sample's rate turns the sensor over the interval
    before it), so a gyro sampled at the instant reads half a sample early: expected delay + dt/2. (The fit is
    first order in the delay: at 30 ms and 200 °/s turns it reads about 10 % short.)"""
    rec = moving(duration=30.0, rate=200.0, seed=4, bias=0.0)
    mag = delayed_field(rec, delay_samples)
    lat = LatencyEstimator()
    assert lat.delay(0.0) == 0.0  # no motion yet: the prior
    for g, m, dt in zip(rec.gyr.tolist(), mag.tolist(), rec.dt.tolist(), strict=True):
        rv = (g[0] * dt, g[1] * dt, g[2] * dt)
        lat.add(from_rotvec(*rv), rv, dt, (m[0], m[1], m[2]))
    assert lat.windows > 200
    assert lat.delay(0.0) == pytest.approx((delay_samples + 0.5) / 200.0, abs=0.003)


@pytest.mark.parametrize("hard_iron_ut", [(0.0, 0.0, 0.0), (20.0, 0.0, -10.0), (0.0, 28.0, -21.0)])
def test_latency_fit_is_not_misled_by_an_uncalibrated_field(hard_iron_ut: tuple[float, float, float]) -> None:
    """A field 10 ms late with a hard iron of up to 35 µT still in it (the magnetometer not calibrated yet): the joint
    fit finds the latency as on a calibrated field, and its σ shrinks from the prior's to a few ms with the turns.
    Its σ before any turn is the prior's (the range 0–100 ms)."""
    rec = moving(duration=30.0, rate=200.0, seed=4, bias=0.0)
    mag = delayed_field(rec, 2) + np.asarray(hard_iron_ut) * 1e-6
    lat = LatencyEstimator()
    assert lat.sd(0.0) == pytest.approx(0.1 / np.sqrt(12.0))
    for g, m, dt in zip(rec.gyr.tolist(), mag.tolist(), rec.dt.tolist(), strict=True):
        rv = (g[0] * dt, g[1] * dt, g[2] * dt)
        lat.add(from_rotvec(*rv), rv, dt, (m[0], m[1], m[2]))
    assert lat.delay(0.0) == pytest.approx(2.5 / 200.0, abs=0.003)
    assert lat.sd(0.0) < 0.003


def test_latency_estimate_holds_at_rest_and_skips_gaps() -> None:
    lat = LatencyEstimator()
    m = (0.0, 20e-6, -40e-6)
    for _ in range(500):  # at rest: windows carry no information
        lat.add(IDENTITY_Q, (0.0, 0.0, 0.0), 0.01, m)
    assert lat.windows > 40
    assert lat.delay(0.013) == pytest.approx(0.013)
    before = lat.windows
    lat.add(IDENTITY_Q, (0.0, 0.0, 0.0), 0.05, m)
    lat.add(IDENTITY_Q, (0.0, 0.0, 0.0), 0.5, m)  # a hole: no window spans it
    assert lat.windows == before
    lat.add(IDENTITY_Q, (0.0, 0.0, 0.0), 0.1, m)  # the window started after the hole counts
    assert lat.windows == before + 1


@pytest.mark.slow
def test_riann_compensates_estimated_latency() -> None:
    """A field 20 ms late: with the online estimate RIANN's 9D heading follows the true heading much more
    closely than with the latency uncompensated, and /diagnostics shows the estimate."""
    rec = moving(duration=30.0, rate=200.0, seed=4, bias=0.0)
    assert rec.quat_ref is not None
    mag = delayed_field(rec, 4)
    errs = {}
    for on in (True, False):
        est = create("riann", estimate_mag_delay=on)
        q = est.update_batch(rec.acc, rec.gyr, rec.dt, mag)
        e = np.degrees(quat.heading_error(rec.quat_ref, q))[len(rec) // 2:]
        errs[on] = float(np.sqrt(np.mean(e ** 2)))
        diag = est.diagnostics()["magnetometer latency (ms)"]
        assert diag.endswith("(estimated)" if on else "(fixed)")
        # (RIANN's gyro increments interpolate point samples: no half-sample shift here)
        assert float(diag.split()[0]) == pytest.approx(20.0 if on else 0.0, abs=4.0)
    assert errs[True] < 0.5 * errs[False]
