"""The 9D path end to end, every estimator with a magnetometer: the stream per sample as in a batch with a field,
use_mag false as 6D, VQF's 9D, the evaluator's 9D rows."""

from __future__ import annotations

import itertools
import math

import numpy as np
import pytest
from helpers_mag import (
    ESTIMATORS,
    STREAM_TOL,
    heading_change_deg,
    moving,
    per_sample,
    rot_z,
    sign_aligned,
    skip_without_mag,
    static,
)

from riann_ros import evaluation as ev
from riann_ros import quaternion as quat
from riann_ros.estimators import create
from riann_ros.magcal.input import FIELD_OFF, USABLE_MAX_T, USABLE_MIN_T, MagConfig
from riann_ros.recording import Recording
from riann_ros.stream import EstimatorStream, GateConfig


def mixed_sequence() -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """12 s at 100 Hz with a gap longer than max_dt and a clock jump back, and a field that starts late, has NaN
    rows, implausible rows and a 2 s stretch without any."""
    rec = moving(duration=12.0, seed=5)
    assert rec.mag is not None
    keep = np.ones(len(rec), dtype=bool)
    keep[700:760] = False  # 0.6 s: a gap (estimator restart) in the IMU stream
    mag = rec.mag.copy()
    mag[:150] = np.nan  # 6D start
    mag[::4] = np.nan  # a slower magnetometer
    mag[300] = 0.0
    mag[301] = [0.0, 2e-3, 0.0]
    mag[450:650] = np.nan  # no field for 2 s
    stamps = rec.stamps_ns.copy()
    stamps[1000:] -= 5 * 10**9  # the clock jumps back (a bag loop): estimator and field state restart
    return stamps[keep], rec.acc[keep], rec.gyr[keep], mag[keep]


@pytest.mark.slow
@pytest.mark.parametrize("name", ESTIMATORS)
def test_stream_process_equals_batch_with_field(name: str) -> None:
    skip_without_mag(name)
    stamps, acc, gyr, mag = mixed_sequence()
    gate = GateConfig(nominal_rate=100.0)
    tol = STREAM_TOL.get(name, 1e-6)

    batch_stream = EstimatorStream(create(name), gate)
    qb, ok_b = batch_stream.process_batch(stamps, acc, gyr, mag)
    one_stream = EstimatorStream(create(name), gate)
    qs, ok_s = per_sample(one_stream, stamps, acc, gyr, mag)
    assert ok_b.all() and ok_s.all()
    assert batch_stream.gate.resets == one_stream.gate.resets == {"start": 1, "gap": 1, "clock_jump": 1}
    np.testing.assert_allclose(sign_aligned(qb, qs), qb, rtol=0, atol=tol)
    usable = np.isfinite(mag).all(axis=1) & (np.linalg.norm(mag, axis=1) > USABLE_MIN_T)
    usable &= np.linalg.norm(mag, axis=1) < USABLE_MAX_T
    assert batch_stream.mag.samples_with_field == one_stream.mag.samples_with_field == int(usable.sum())

    # in pieces (the evaluator's chunks), continuing across the calls
    pieces = EstimatorStream(create(name), gate)
    cuts = [0, 333, 455, 900, len(stamps)]
    qp = np.vstack([pieces.process_batch(stamps[a:b], acc[a:b], gyr[a:b], mag[a:b])[0]
                    for a, b in itertools.pairwise(cuts)])
    np.testing.assert_allclose(sign_aligned(qb, qp), qb, rtol=0, atol=tol)

    # the field was used: the 9D output differs from the 6D one
    q6, _ = EstimatorStream(create(name), gate).process_batch(stamps, acc, gyr, None)
    assert heading_change_deg(q6, qb).max() > 1.0


@pytest.mark.parametrize("name", ESTIMATORS)
def test_use_mag_false_is_6d(name: str) -> None:
    skip_without_mag(name)
    stamps, acc, gyr, mag = mixed_sequence()
    gate = GateConfig(nominal_rate=100.0)
    q6, _ = EstimatorStream(create(name), gate).process_batch(stamps, acc, gyr, None)
    off = EstimatorStream(create(name), gate, MagConfig(use_mag="false", declination_deg=10.0))
    q_off, ok = off.process_batch(stamps, acc, gyr, mag)
    assert ok.all()
    np.testing.assert_allclose(q_off, q6, rtol=0, atol=1e-12)
    assert off.mag.samples_with_field == 0 and off.mag.state == FIELD_OFF
    if name != "riann":  # RIANN's per-sample path is covered above; keep the runtime down
        one = EstimatorStream(create(name), gate, MagConfig(use_mag="false"))
        q_one, _ = per_sample(one, stamps, acc, gyr, mag)
        np.testing.assert_allclose(sign_aligned(q6, q_one), q6, rtol=0, atol=1e-6)


def test_vqf_batch_equals_update_with_field() -> None:
    rec = moving(duration=15.0, seed=6)
    assert rec.mag is not None
    mag = rec.mag.copy()
    mag[::5] = np.nan
    mag[3::7] = 0.0
    mag[300:450] = np.nan
    dt = rec.dt
    est = create("vqf")
    qb = est.update_batch(rec.acc, rec.gyr, dt, mag)
    observed_b = est.heading_observed()
    est = create("vqf")
    qs = np.empty_like(qb)
    observed = []
    for i in range(len(rec)):
        m = None if np.isnan(mag[i]).any() else mag[i]  # None rows and NaN rows are the same
        qs[i] = est.update(rec.acc[i], rec.gyr[i], float(dt[i]), m)
        observed.append(est.heading_observed())
    np.testing.assert_allclose(qs, qb, rtol=0, atol=1e-9)
    assert observed[-1] == observed_b
    has = np.isfinite(mag).all(axis=1) & (np.abs(mag).sum(axis=1) > 0)
    assert not np.array(observed)[~has].any()  # no field (None, NaN, zero): the heading follows the gyro
    assert any(observed)  # VQF accepts the field once it has seen it during motion
    # continuing batches
    est = create("vqf")
    qp = np.vstack([est.update_batch(rec.acc[a:a + 250], rec.gyr[a:a + 250], dt[a:a + 250], mag[a:a + 250])
                    for a in range(0, len(rec), 250)])
    np.testing.assert_allclose(qp, qb, rtol=0, atol=1e-9)


def test_vqf_mag_none_is_quat6d() -> None:
    from vqf import VQF

    rec = moving(duration=10.0, seed=8)
    ts = 0.01
    q = create("vqf").update_batch(rec.acc, rec.gyr, np.full(len(rec), ts))
    v = create("vqf")
    assert not v.heading_observed()
    ref = VQF(ts).updateBatch(np.ascontiguousarray(rec.gyr), np.ascontiguousarray(rec.acc))["quat6D"]
    np.testing.assert_allclose(q, ref, rtol=0, atol=1e-12)
    # all-NaN mag rows are the same as no mag
    v = create("vqf")
    q_nan = v.update_batch(rec.acc, rec.gyr, np.full(len(rec), ts), np.full((len(rec), 3), np.nan))
    np.testing.assert_allclose(q_nan, ref, rtol=0, atol=1e-12)
    assert not v.heading_observed()


def test_vqf_9d_heading_is_magnetic_north() -> None:
    q_true = quat.multiply(rot_z(math.radians(-130.0)), quat.from_rotvec(np.radians([5.0, 20.0, 0.0])))
    rec = static(q_true, 1500)
    est = create("vqf")
    q = est.update_batch(rec.acc, rec.gyr, rec.dt, rec.mag)
    # (heading_observed() stays False here: VQF learns its field reference only during motion, at rest it
    # converges through its initial gain alone)
    assert np.degrees(quat.heading_error(q_true, q[-1])) < 1.0
    assert np.degrees(quat.inclination_error(q_true, q[-1])) < 1.0


def evaluate(rec: Recording, use_mag: str) -> list[ev.ResultRow]:
    settings = ev.EvalSettings(estimators=ev.parse_estimators("riann,vqf"), scenarios=[ev.AS_RECORDED],
                               use_mag=use_mag)
    res = ev.evaluate_source("x.mcap", settings, runner=ev.OfflineRunner(use_mag=use_mag), recording=rec)
    assert res.error is None, res.error
    assert len(res.rows) == 2
    return res.rows


@pytest.mark.slow
def test_evaluator_9d_rows() -> None:
    rec = moving(duration=20.0, seed=12)
    nine = evaluate(rec, "auto")
    for r in nine:
        assert r.sensors == "9D", r.estimator
        assert r.stats.mag_samples == len(rec)
        assert r.score.heading_rmse_deg is not None and r.score.heading_rmse_deg < 3.0
        assert r.score.total_rmse_deg is not None and r.score.total_rmse_deg >= r.rmse_deg - 1e-9
        d = r.to_dict()
        assert d["sensors"] == "9D" and "heading_rmse_deg" in d and "total_rmse_deg" in d
    six = evaluate(rec, "false")
    for r in six:
        assert r.sensors == "6D", r.estimator
        assert r.stats.mag_samples == 0
        assert r.score.heading_rmse_deg is None and r.score.total_rmse_deg is None
        assert "heading_rmse_deg" not in r.to_dict()
    # the field changes the heading only: the inclination scores are those of the 6D runs
    for a, b in zip(nine, six, strict=True):
        assert a.estimator == b.estimator
        assert a.rmse_deg == pytest.approx(b.rmse_deg, abs=1e-6)
    # "auto" on a recording without a magnetometer: 6D
    rec.mag = None
    assert [r.sensors for r in evaluate(rec, "auto")] == ["6D", "6D"]
