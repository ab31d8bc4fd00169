"""Perturbations of the evaluator (riann_ros.evaluation.perturb): jitter, rate, bias, dropout, conditions."""

from __future__ import annotations

import itertools

import numpy as np
import pytest

from riann_ros import quaternion as quat
from riann_ros.evaluation import perturb as pt
from riann_ros.recording import Recording


def linear(n: int = 2000, rate: float = 200.0, t0_ns: int = 10**9) -> Recording:
    """acc and gyr linear in time (so interval means are known exactly), a slowly turning reference."""
    t = np.arange(n) / rate
    acc = np.column_stack([1.0 + 2.0 * t, -0.5 * t, 9.81 + 0 * t])
    gyr = np.column_stack([0.1 * t, 0.2 + 0 * t, -0.3 * t])
    ref = quat.from_rotvec(np.column_stack([0.1 * t, 0 * t, 0 * t]))
    mask = (t % 10.0) > 2.0  # 2 s of rest every 10 s
    stamps = t0_ns + np.round(t * 1e9).astype(np.int64)
    return Recording(stamps, acc, gyr, ref, mask, name="lin")


def run(p: pt.Perturbation, rec: Recording, chunks: list[int] | None = None, seed: int = 0) -> tuple[Recording, dict]:
    tr = p.start(np.random.default_rng(seed))
    bounds = [0, *(chunks or []), len(rec)]
    parts = [tr(rec.slice(a, b)) for a, b in itertools.pairwise(bounds)]
    return pt.concat(*[q for q in parts if len(q)]), tr.info()


def test_parse_conditions_and_errors():
    c = pt.parse_condition("jitter:10/20/30ms+bias:3,3,0")
    assert c.label == "jitter:10/20/30ms+bias:3,3,0"
    assert c.nominal_rate(285.7) == pytest.approx(50.0)
    assert pt.parse_condition("none").label == "none" and pt.parse_condition("").parts == ()
    assert pt.parse_perturbation("jitter:8-32ms") == pt.Jitter(lo=0.008, hi=0.032)
    assert pt.parse_perturbation("rate:50").text() == "rate:50"
    assert pt.parse_perturbation("jitter:5-15ms:points") == pt.Jitter(lo=0.005, hi=0.015, points=True)
    assert pt.parse_perturbation("rate:50:points").text() == "rate:50:points"
    assert pt.parse_perturbation("bias:random:2") == pt.Bias(sigma=2.0)
    assert pt.parse_perturbation("bias:-1,0.5,0").text() == "bias:-1,0.5,0"
    assert pt.parse_perturbation("dropout:0.1-0.6s@10s") == pt.Dropout(0.1, 0.6, 10.0)
    assert pt.parse_perturbation("latency:0-20ms") == pt.Latency(0.0, 0.02)
    assert pt.parse_perturbation("fifo:20ms") == pt.Fifo(0.02) and pt.Fifo(0.02).text() == "fifo:20ms"
    for bad in ("jitter:0ms", "jitter:30-10ms", "rate:-5", "bias:1,2", "dropout:0.6-0.1s@10s", "noise:1",
                "latency:20-10ms", "latency:5ms", "fifo:0ms", "fifo:1-2ms", "bias:1,2,3:points", "jitter:5ms:means"):
        with pytest.raises(ValueError, match="bad perturbation"):
            pt.parse_perturbation(bad)


def test_jitter_intervals_from_the_set_and_exact_interval_means():
    rec = linear()
    out, info = run(pt.parse_perturbation("jitter:10/20/30ms"), rec)
    steps = np.diff(out.stamps_ns)
    assert set(steps.tolist()) == {10_000_000, 20_000_000, 30_000_000}
    assert info["samples"] == len(out) and abs(np.mean(steps) - 2e7) < 1e6
    assert out.stamps_ns[0] == rec.stamps_ns[0] and out.stamps_ns[-1] <= rec.stamps_ns[-1]
    # a linear signal's mean over (a, b] is its value at (a + b) / 2
    mid = 0.5 * (out.stamps_ns[1:] + out.stamps_ns[:-1])
    t_mid = (mid - rec.stamps_ns[0]) * 1e-9
    np.testing.assert_allclose(out.acc[1:, 0], 1.0 + 2.0 * t_mid, atol=1e-9)
    np.testing.assert_allclose(out.gyr[1:, 2], -0.3 * t_mid, atol=1e-9)
    # the reference is slerped at the sample time, the mask is the nearest sample's
    t = (out.stamps_ns - rec.stamps_ns[0]) * 1e-9
    np.testing.assert_allclose(quat.total_error(out.quat_ref, quat.from_rotvec(np.outer(0.1 * t, [1, 0, 0]))), 0,
                               atol=1e-9)
    assert (out.score_mask == ((t % 10.0) > 2.0)).mean() > 0.99


def test_jitter_points_are_the_signal_at_the_new_stamps():
    rec = linear()
    means, _ = run(pt.parse_perturbation("jitter:10/20/30ms"), rec)
    out, _ = run(pt.parse_perturbation("jitter:10/20/30ms:points"), rec)
    np.testing.assert_array_equal(out.stamps_ns, means.stamps_ns)  # the same stamps for the same seed
    t = (out.stamps_ns - rec.stamps_ns[0]) * 1e-9
    np.testing.assert_allclose(out.acc[:, 0], 1.0 + 2.0 * t, atol=1e-9)
    np.testing.assert_allclose(out.gyr[:, 2], -0.3 * t, atol=1e-9)
    np.testing.assert_allclose(out.quat_ref, means.quat_ref, atol=1e-12)


def test_jitter_range_averages_a_fast_signal_and_upsamples_a_slow_one():
    rec = linear()
    out, _ = run(pt.parse_perturbation("jitter:8-32ms"), rec)
    steps = np.diff(out.stamps_ns)
    assert steps.min() >= 8_000_000 and steps.max() <= 32_000_000 and len(set(steps.tolist())) > 100
    fast, _ = run(pt.parse_perturbation("rate:1000"), rec)  # 5x the recording's rate: linear interpolation
    assert set(np.diff(fast.stamps_ns).tolist()) == {1_000_000}
    t = (fast.stamps_ns - rec.stamps_ns[0]) * 1e-9
    np.testing.assert_allclose(fast.gyr[1:, 0], 0.1 * (t[1:] - 0.0005), atol=1e-9)


def test_rate_gives_exact_ns_stamps():
    rec = linear()
    out, _ = run(pt.parse_perturbation("rate:50"), rec)
    assert set(np.diff(out.stamps_ns).tolist()) == {20_000_000}
    third, _ = run(pt.parse_perturbation("rate:300"), rec)
    assert set(np.diff(third.stamps_ns).tolist()) == {3_333_333, 3_333_334}
    k = np.arange(len(third))
    np.testing.assert_array_equal(third.stamps_ns, rec.stamps_ns[0] + np.round(k * 1e9 / 300).astype(np.int64))


@pytest.mark.parametrize("text", ["jitter:10/20/30ms", "jitter:3-7ms", "jitter:3-7ms:points", "rate:77",
                                  "dropout:0.1-0.6s@2s", "bias:random:2", "latency:0-20ms", "fifo:23ms"])
def test_chunked_equals_whole(text):
    rec = linear(n=5000)
    whole, info_w = run(pt.parse_perturbation(text), rec, seed=5)
    chunked, info_c = run(pt.parse_perturbation(text), rec, [1, 2, 700, 701, 2500, 4999], seed=5)
    np.testing.assert_array_equal(chunked.stamps_ns, whole.stamps_ns)
    np.testing.assert_allclose(chunked.acc, whole.acc, atol=1e-9)
    np.testing.assert_allclose(chunked.gyr, whole.gyr, atol=1e-9)
    np.testing.assert_allclose(chunked.quat_ref, whole.quat_ref, atol=1e-9)
    np.testing.assert_array_equal(chunked.score_mask, whole.score_mask)
    assert info_c == info_w


def test_latency_moves_only_the_stamps_later_and_keeps_them_in_order():
    rec = linear(n=4000, rate=200.0)
    out, info = run(pt.parse_perturbation("latency:0-20ms"), rec, seed=4)
    delay = (out.stamps_ns - rec.stamps_ns) * 1e-9
    assert delay.min() >= 0.0 and delay.max() <= 0.020 + 4e-6
    assert np.diff(out.stamps_ns).min() >= 1000  # in order, never repeated
    assert np.diff(out.stamps_ns).std() * 1e-9 > 0.005  # the steps jitter (5 ms regular underneath)
    assert abs(delay.mean() - 0.010) < 0.002  # mostly the drawn delay (order rarely pushes a stamp)
    for name in ("acc", "gyr", "quat_ref", "score_mask"):
        np.testing.assert_array_equal(getattr(out, name), getattr(rec, name))
    assert info == {"samples": len(rec)}


def test_fifo_stamps_each_sample_at_the_first_read_at_or_after_it():
    rec = linear(n=4000, rate=200.0)
    out, info = run(pt.parse_perturbation("fifo:23ms"), rec)
    delay = (out.stamps_ns - rec.stamps_ns) * 1e-9
    assert delay.min() >= 0.0 and delay.max() < 0.023 + 6 * 1e-5  # at most one read period (+ 10 µs per message)
    steps = np.diff(out.stamps_ns)
    assert steps.min() == 10_000  # messages of one read 10 µs apart
    big = steps[steps > 1_000_000]  # one step per read: 23 ms apart (less the messages' 10 µs spacing)
    assert np.all(np.abs(big - 23_000_000) <= 60_000)
    assert info == {"samples": len(rec), "reads": len(big) + 1}
    for name in ("acc", "gyr", "quat_ref", "score_mask"):
        np.testing.assert_array_equal(getattr(out, name), getattr(rec, name))


def test_bias_constant_and_random_per_seed():
    rec = linear()
    out, info = run(pt.parse_perturbation("bias:3,3,0"), rec)
    np.testing.assert_allclose(out.gyr - rec.gyr, np.tile(np.radians([3.0, 3.0, 0.0]), (len(rec), 1)), atol=1e-15)
    assert info == {"bias_dps": [3.0, 3.0, 0.0]}
    _, ia = run(pt.parse_perturbation("bias:random:2"), rec, seed=1)
    _, ib = run(pt.parse_perturbation("bias:random:2"), rec, seed=1)
    _, ic = run(pt.parse_perturbation("bias:random:2"), rec, seed=2)
    assert ia == ib != ic
    draws = np.array([run(pt.Bias(sigma=2.0), rec.slice(0, 2), seed=s)[1]["bias_dps"] for s in range(400)])
    assert abs(draws.std() - 2.0) < 0.15 and abs(draws.mean()) < 0.2


def test_dropout_holes_start_in_motion_and_have_the_drawn_lengths():
    rec = linear(n=200 * 300)  # 5 min at 200 Hz
    out, info = run(pt.parse_perturbation("dropout:0.1-0.6s@10s"), rec, seed=3)
    steps = np.diff(out.stamps_ns) * 1e-9
    holes = np.flatnonzero(steps > 0.006)
    assert len(holes) == info["holes"] and 15 <= len(holes) <= 50  # about one every 10 s
    assert np.all((steps[holes] >= 0.1) & (steps[holes] <= 0.6 + 0.005))
    kept = set(out.stamps_ns.tolist())
    first_missing = [int(np.searchsorted(rec.stamps_ns, out.stamps_ns[h])) + 1 for h in holes]
    assert all(rec.score_mask[i] and rec.stamps_ns[i] not in kept for i in first_missing)  # starts in motion
    assert info["samples_removed"] == len(rec) - len(out)


def test_magnetometer_follows_its_samples_through_dropout_and_jitter():
    rec = linear()
    rec.mag = np.column_stack([np.arange(len(rec)) * 1e-9, np.zeros(len(rec)), np.full(len(rec), 40e-6)])
    out, _ = run(pt.parse_condition("dropout:0.1-0.6s@10s").parts[0], rec, chunks=[700, 1500], seed=2)
    kept = np.searchsorted(rec.stamps_ns, out.stamps_ns)
    assert len(out) < len(rec) and np.array_equal(out.mag, rec.mag[kept])
    out, _ = run(pt.parse_condition("jitter:10/20/30ms").parts[0], rec, chunks=[700])
    latest = np.searchsorted(rec.stamps_ns, out.stamps_ns, side="right") - 1  # at or before each new stamp
    assert np.array_equal(out.mag, rec.mag[latest])


def test_magnetic_offset_and_disturbance_window():
    rec = linear()  # 10 s at 200 Hz
    rec.mag = np.tile([20e-6, 0.0, -40e-6], (len(rec), 1))
    cond = pt.parse_condition("magnetic:offset:5,-5,1")
    assert cond.label == "magnetic:offset:5,-5,1"
    out, info = run(cond.parts[0], rec, chunks=[333, 1200])
    np.testing.assert_allclose(out.mag - rec.mag, np.tile([5e-6, -5e-6, 1e-6], (len(rec), 1)), atol=1e-18)
    assert np.array_equal(out.gyr, rec.gyr) and np.array_equal(out.stamps_ns, rec.stamps_ns)
    p = pt.parse_condition("magnetic:disturb:40@2-4.5s").parts[0]
    a, info = run(p, rec, chunks=[100, 700, 1500], seed=3)
    b, _ = run(p, rec, seed=3)  # chunking does not matter
    assert np.array_equal(a.mag, b.mag)
    t = (rec.stamps_ns - rec.stamps_ns[0]) * 1e-9
    on = (t >= 2.0) & (t < 4.5)
    added = a.mag - rec.mag
    assert np.allclose(np.linalg.norm(added[on], axis=1), 40e-6) and not added[~on].any()
    assert np.allclose(added[on], added[on][0])  # one direction per sequence
    assert info["samples"] == on.sum()
    no_mag = linear()
    assert run(p, no_mag)[0].mag is None
    with pytest.raises(ValueError, match="magnetic:disturb"):
        pt.parse_condition("magnetic:disturb:40@5-2s")


def test_perturb_help_and_errors_name_every_kind():
    """The --perturb help and the parse error are built from the definitions: every kind the parser accepts (and the
    :points and :lowpass suffixes) has example forms there, each of which parses, and the CLI help shows every one."""
    from riann_ros.cli.evaluate_parser import build_parser
    from riann_ros.evaluation.perturb import conditions

    kinds = set(conditions._PARSERS)
    assert kinds | {"points", "lowpass"} == set(pt.EXAMPLES) == set(pt.DEFINITIONS) - {"seeding"}
    help_text = " ".join(next(a.help for a in build_parser()._actions if "--perturb" in a.option_strings).split())
    with pytest.raises(ValueError) as err:
        pt.parse_perturbation("nonsense:1")
    for kind, forms in pt.EXAMPLES.items():
        assert forms, kind
        for form in forms:
            text = form.split(" (")[0]  # without the unit note
            p = pt.parse_perturbation(text)
            assert text.startswith(p.kind) and (kind == "points") == text.endswith(":points")
            assert form in help_text and form in str(err.value)
    assert {f.split(":")[0] for forms in pt.EXAMPLES.values() for f in forms} == kinds


def test_rate_lowpass_is_a_first_order_filter_sampled_at_the_stamp():
    """rate:HZ:lowpass: a ramp comes out settled half a step late (the filter's lag tau = T/2), a step input as
    1 - exp(-t/tau); stamps and reference as rate:HZ:points; chunked equals whole."""
    rec = linear(n=4000)  # gyr x = 0.1 t at 200 Hz
    lp = pt.parse_perturbation("rate:50:lowpass")
    assert lp.text() == "rate:50:lowpass" and "rate:50:lowpass" in pt.accepted_forms()
    out, _ = run(lp, rec)
    pts, _ = run(pt.parse_perturbation("rate:50:points"), rec)
    np.testing.assert_array_equal(out.stamps_ns, pts.stamps_ns)
    np.testing.assert_allclose(out.quat_ref, pts.quat_ref, atol=1e-12)
    t = (out.stamps_ns - rec.stamps_ns[0]) * 1e-9
    settled = t > 0.2  # 20 time constants of 10 ms
    np.testing.assert_allclose(out.gyr[settled, 0], 0.1 * (t[settled] - 0.010), atol=1e-9)
    assert abs(out.gyr[1, 0] - 0.1 * (t[1] - 0.010 * (1 - np.exp(-t[1] / 0.010)))) < 1e-9
    chunked, _ = run(lp, rec, [1, 2, 700, 701, 2500, 3999])
    np.testing.assert_allclose(chunked.gyr, out.gyr, atol=1e-9)
    np.testing.assert_allclose(chunked.acc, out.acc, atol=1e-9)
    for bad in ("jitter:5-15ms:lowpass", "rate:50:points:lowpass"):
        with pytest.raises(ValueError):
            pt.parse_perturbation(bad)
