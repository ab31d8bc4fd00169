"""Reproducible lies in the evaluator (issue 46): a late magnetometer (``magnetic:lag:D``) and a gyro unit slip
(``gyro:scale:F``) as perturbations (riann_ros.evaluation.perturb), and both through ``riann-bag-eval``."""

from __future__ import annotations

import itertools
import json

import numpy as np
import pytest

from riann_ros import bagio
from riann_ros import quaternion as quat
from riann_ros.cli.evaluate import main
from riann_ros.evaluation import perturb as pt
from riann_ros.magcal.synthetic import FIELD_ENU_T, ground_robot
from riann_ros.recording import Recording

RATE = 200.0


def known_field(n: int = 4000, t0_ns: int = 10**9) -> tuple[Recording, np.ndarray]:
    """A recording at 200 Hz whose field is linear in time (so a lagged field is known exactly at any time):
    f(t) = a + b t; returns it and (a, b) stacked."""
    t = np.arange(n) / RATE
    ab = np.array([[20e-6, -3e-6, -40e-6], [1e-6, 0.5e-6, -0.2e-6]])
    mag = ab[0] + t[:, None] * ab[1]
    acc = np.tile([0.0, 0.0, 9.81], (n, 1))
    gyr = np.column_stack([0.1 * np.sin(t), 0.2 + 0 * t, -0.3 * t])
    ref = quat.from_rotvec(np.column_stack([0.1 * t, 0 * t, 0 * t]))
    stamps = t0_ns + np.round(t * 1e9).astype(np.int64)
    return Recording(stamps, acc, gyr, ref, (t % 10.0) > 2.0, name="field", mag=mag), ab


def run(p: pt.Perturbation, rec: Recording, chunk: int | None = None) -> tuple[Recording, dict]:
    tr = p.start(np.random.default_rng(0))
    size = chunk or len(rec)
    parts = [tr(rec.slice(a, a + size)) for a in range(0, len(rec), size)]
    return pt.concat(*[q for q in parts if len(q)]), tr.info()


@pytest.mark.parametrize("text, lag", [("magnetic:lag:300ms", 0.3), ("magnetic:lag:0.1s", 0.1),
                                       ("magnetic:lag:203.7ms", 0.2037)])
def test_lag_delays_the_field_by_exactly_the_lag_whatever_the_chunking(text, lag):
    rec, ab = known_field()
    p = pt.parse_perturbation(text)
    assert p == pt.MagneticLag(lag) and pt.parse_perturbation(p.text()) == p
    out, info = run(p, rec, 1000)
    t = (rec.stamps_ns - rec.stamps_ns[0]) * 1e-9
    early = t < lag - 1e-9  # no field of lag s earlier: no reading
    assert np.isnan(out.mag[early]).all() and np.isfinite(out.mag[~early]).all()
    np.testing.assert_allclose(out.mag[~early], ab[0] + (t[~early] - lag)[:, None] * ab[1], rtol=0, atol=1e-17)
    assert info == {"lag_s": lag, "samples": len(rec), "samples_before_lag": int(early.sum())}
    for name in ("stamps_ns", "acc", "gyr", "quat_ref", "score_mask"):  # only the magnetometer changes
        np.testing.assert_array_equal(getattr(out, name), getattr(rec, name))
    for chunk in (37, 1):
        other, other_info = run(p, rec, chunk)
        np.testing.assert_array_equal(other.mag, out.mag)
        assert other_info == info


def test_lag_of_whole_steps_is_the_recording_shifted():
    rec, _ = known_field()
    rec.mag = rec.mag + 1e-6 * np.sin(np.arange(len(rec)) * 0.37)[:, None]  # any field: not linear
    out, _ = run(pt.parse_perturbation("magnetic:lag:300ms"), rec, 37)
    k = round(0.3 * RATE)  # 60 samples
    np.testing.assert_allclose(out.mag[k:], rec.mag[:-k], rtol=0, atol=1e-20)


def test_lag_holds_the_earlier_reading_where_the_later_has_none_and_keeps_holes():
    rec, _ = known_field(n=400)
    rec.mag[100:110] = np.nan  # a stretch without a field
    out, _ = run(pt.parse_perturbation("magnetic:lag:12.5ms"), rec)  # 2.5 steps
    # t - lag between samples 97 and 98 (k = 100): both have a field → linear between them
    np.testing.assert_allclose(out.mag[100], 0.5 * (rec.mag[97] + rec.mag[98]), rtol=0, atol=1e-18)
    # k = 102: between 99 (a field) and 100 (none): the earlier one
    np.testing.assert_array_equal(out.mag[102], rec.mag[99])
    assert np.isnan(out.mag[103:113]).all()  # between 100..109 (none) and the next
    np.testing.assert_allclose(out.mag[113], 0.5 * (rec.mag[110] + rec.mag[111]), rtol=0, atol=1e-18)


def test_lag_combines_with_an_offset_and_leaves_a_recording_without_magnetometer():
    rec, ab = known_field()
    cond = pt.parse_condition("magnetic:lag:200ms+magnetic:offset:20,0,-10")
    assert cond.label == "magnetic:lag:200ms+magnetic:offset:20,0,-10"
    trs = cond.start([np.random.default_rng(k) for k in range(2)])
    out = rec
    for tr in trs:
        out = tr(out)
    t = (rec.stamps_ns - rec.stamps_ns[0]) * 1e-9
    late = t >= 0.2 - 1e-9
    want = ab[0] + (t[late] - 0.2)[:, None] * ab[1] + np.array([20e-6, 0.0, -10e-6])
    np.testing.assert_allclose(out.mag[late], want, rtol=0, atol=1e-17)
    no_mag = known_field(n=50)[0]
    no_mag.mag = None
    assert run(pt.parse_perturbation("magnetic:lag:300ms"), no_mag)[0].mag is None


def test_gyro_scale_multiplies_the_gyro_from_the_first_sample():
    rec, _ = known_field()
    for text, factor in (("gyro:scale:57.2958", 57.2958), ("gyro:scale:0.001", 0.001), ("gyro:scale:-1", -1.0)):
        p = pt.parse_perturbation(text)
        assert p == pt.GyroScale(factor) and p.text() == text
        out, info = run(p, rec, 37)
        np.testing.assert_array_equal(out.gyr, rec.gyr * factor)
        for name in ("stamps_ns", "acc", "mag", "quat_ref", "score_mask"):
            np.testing.assert_array_equal(getattr(out, name), getattr(rec, name))
        assert info == {"factor": factor, "samples": len(rec)}


@pytest.mark.parametrize("bad", ["gyro:scale:0", "gyro:scale:", "gyro:57.3", "gyro:scale:1,2", "magnetic:lag:0ms",
                                 "magnetic:lag:300", "magnetic:lag:-5ms", "magnetic:lag:1-2s"])
def test_bad_lag_and_scale_are_refused_naming_the_forms(bad):
    with pytest.raises(ValueError, match="bad perturbation") as err:
        pt.parse_perturbation(bad)
    assert "gyro:scale:57.2958" in str(err.value) and "magnetic:lag:300ms" in str(err.value)


def robot_bag(tmp_path, seconds: float = 40.0):
    """A ground robot turning back and forth with an undistorted field: its 9D heading is good as recorded."""
    phases = [("rest", 2.0, 0.0)] + [("turn", 4.0, 90.0), ("turn", 4.0, -90.0)] * int(seconds / 8)
    rec = ground_robot(phases, rate_hz=RATE, mount_rpy_deg=(10.0, -5.0, 0.0), gyr_noise=0.002, seed=1)
    field = np.broadcast_to(np.asarray(FIELD_ENU_T), (len(rec), 3))
    rec.mag = quat.rotate(quat.conjugate(rec.quat_ref), field)
    rec.stamps_ns = rec.stamps_ns + 10**9
    return bagio.write_recording(tmp_path / "robot.mcap", rec)


def test_lag_and_scale_through_the_command_line(tmp_path, capsys):
    """riann-bag-eval -p magnetic:lag:300ms -p gyro:scale:57.2958 on a 9D recording of a robot turning about the
    vertical: the late field (until the lag scan compensates it) and the unit slip each turn the heading; results.json
    records what each did; the --perturb help names both."""
    bag = robot_bag(tmp_path)
    out = tmp_path / "eval"
    conditions = ["none", "magnetic:lag:300ms", "gyro:scale:57.2958"]
    args = [str(bag), "-e", "vqf:mag_calibration=false", "-s", "as-recorded", *itertools.chain(
        *(("-p", c) for c in conditions)), "--no-plots", "-q", "--out", str(out)]
    assert main(args) == 0
    data = json.loads((out / "results.json").read_text())
    rows = {r["perturbation"]: r for r in data["results"]}
    assert sorted(rows) == sorted(conditions) and all(r["sensors"] == "9D" for r in rows.values())
    base, late, slip = rows["none"], rows["magnetic:lag:300ms"], rows["gyro:scale:57.2958"]
    # the late field turns the heading until the lag scan has its windows and compensates it (magcal/lag.py)
    assert base["heading_rmse_deg"] < 1.0 and late["heading_rmse_deg"] > base["heading_rmse_deg"] + 1.0
    assert abs(late["rmse_deg"] - base["rmse_deg"]) < 0.1  # the inclination does not use the field
    assert slip["heading_rmse_deg"] > 45.0  # turns about the vertical only: the slip turns the heading
    did = data["sequences"][0]["perturbations"]
    n = base["n_samples"]
    assert did["magnetic:lag:300ms"]["as-recorded"] == [{"perturbation": "magnetic:lag:300ms", "lag_s": 0.3,
                                                        "samples": n, "samples_before_lag": 60}]
    assert did["gyro:scale:57.2958"]["as-recorded"] == [{"perturbation": "gyro:scale:57.2958", "factor": 57.2958,
                                                        "samples": n}]
    capsys.readouterr()
    with pytest.raises(SystemExit):
        main(["--help"])
    help_text = " ".join(capsys.readouterr().out.split())
    assert "gyro:scale:57.2958" in help_text and "magnetic:lag:300ms" in help_text


def test_lag_starts_over_where_the_clock_goes_back():
    rec, _ = known_field(n=400)
    rec.stamps_ns = np.concatenate([rec.stamps_ns[:200], rec.stamps_ns[:200]])  # back to the start at sample 200
    p = pt.parse_perturbation("magnetic:lag:100ms")
    whole, info = run(p, rec)
    k = round(0.1 * RATE)
    none = np.isnan(whole.mag).all(axis=1)
    assert np.array_equal(np.flatnonzero(none), np.r_[0:k, 200:200 + k]) and info["samples_before_lag"] == 2 * k
    np.testing.assert_allclose(whole.mag[200 + k:], rec.mag[200:-k], rtol=0, atol=1e-20)
    np.testing.assert_allclose(whole.mag[k:200], rec.mag[:200 - k], rtol=0, atol=1e-20)
    for chunk in (37, 1, 200):
        other, other_info = run(p, rec, chunk)
        np.testing.assert_array_equal(other.mag, whole.mag)
        assert other_info == info
