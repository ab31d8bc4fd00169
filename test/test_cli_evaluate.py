"""riann-bag-eval end to end: bags in, table and files out, bad input, and the BROAD acceptance check."""

from __future__ import annotations

import importlib.resources
import json
from pathlib import Path

import numpy as np
import pytest
from test_evaluation import synthetic

from riann_ros import evaluation as ev
from riann_ros.cli.evaluate import main
from riann_ros.datasets.synthetic import generate
from riann_ros.evaluation.estimate_bags import topic_for
from riann_ros.magcal.synthetic import distort

bagio = pytest.importorskip("riann_ros.bagio")


def make_bag(tmp: Path, name: str, **kw) -> Path:
    rec = synthetic(name=name, t0_ns=1_700_000_000_000_000_000, **kw)
    return bagio.write_recording(tmp / f"{name}.mcap", rec)


@pytest.fixture(scope="module")
def bags(tmp_path_factory) -> list[Path]:
    d = tmp_path_factory.mktemp("bags")
    return [make_bag(d, "seq_a"), make_bag(d, "seq_b", gyr_bias=(-0.01, 0.0, 0.02))]


@pytest.mark.slow
def test_offline_run_writes_table_and_files(bags, tmp_path, capsys):
    out = tmp_path / "out"
    rc = main(
        [
            *map(str, bags),
            "--estimators",
            "riann,madgwick:beta=0.033,madgwick:beta=0.1",
            "--out",
            str(out),
            "--heading",
            "-q",
        ]
    )
    assert rc == 0
    text = capsys.readouterr().out
    for word in ("realistic", "partially-restrictive", "restrictive", "madgwick(beta=0.1)", "mean", "median", "max"):
        assert word in text
    for f in (
        "results.csv",
        "results.json",
        "report.md",
        "rmse_boxplots.png",
        "rmse_boxplots.svg",
        "error_over_time.png",
        "error_over_time.svg",
    ):
        assert (out / f).is_file(), f
    data = json.loads((out / "results.json").read_text())
    assert len(data["results"]) == 2 * 3 * 4  # sequences × estimators × scenarios (the paper's three + as-recorded)
    assert data["settings"]["seed"] == 0
    assert data["versions"]["riann_model"]["sha256"]
    seq = {s["name"]: s for s in data["sequences"]}
    bias = seq["seq_a"]["scenarios"]["realistic"]["bias_added_dps"]
    np.testing.assert_allclose(bias, np.degrees(ev.random_bias(0, "seq_a")), atol=1e-5)
    assert seq["seq_a"]["scenarios"]["restrictive"]["bias_removed_dps"] != [0.0, 0.0, 0.0]
    row = data["results"][0]
    assert {"rmse_deg", "heading_rmse_deg", "total_rmse_deg", "n_scored"} <= set(row)
    assert "heading_rmse_deg" in (out / "results.csv").read_text().splitlines()[0]
    assert "| realistic |" in (out / "report.md").read_text()


@pytest.mark.slow
def test_same_seed_same_numbers_parallel_or_not(bags, tmp_path):
    a, b = tmp_path / "a", tmp_path / "b"
    args = ["--estimators", "madgwick", "--scenarios", "partially-restrictive", "--no-plots", "-q"]
    assert main([*map(str, bags), *args, "--out", str(a)]) == 0
    assert main([*map(str, bags), *args, "--out", str(b), "--jobs", "2"]) == 0
    ra = json.loads((a / "results.json").read_text())["results"]
    rb = json.loads((b / "results.json").read_text())["results"]
    assert [r["rmse_deg"] for r in ra] == [r["rmse_deg"] for r in rb]


def test_bad_inputs_are_named_and_others_still_evaluated(bags, tmp_path, capsys):
    garbage = tmp_path / "garbage.mcap"
    garbage.write_bytes(b"not a bag at all")
    truncated = tmp_path / "truncated.mcap"
    truncated.write_bytes(bags[0].read_bytes()[:5000])
    rec = synthetic(name="noref", t0_ns=10**18)
    rec.quat_ref = None
    noref = bagio.write_recording(tmp_path / "noref.mcap", rec)
    rec = synthetic(name="unscored", t0_ns=10**18)
    rec.score_mask[:] = False
    unscored = bagio.write_recording(tmp_path / "unscored.mcap", rec)
    missing = tmp_path / "missing.mcap"
    rc = main(
        [
            str(bags[0]),
            str(garbage),
            str(truncated),
            str(noref),
            str(unscored),
            str(missing),
            "--estimators",
            "madgwick",
            "--scenarios",
            "realistic",
            "-q",
        ]
    )
    assert rc == 1
    cap = capsys.readouterr()
    # the bag without a reference is evaluated, not scored (test_evaluation_free.py); the others fail by name
    assert "2 of 6 input(s) evaluated" in cap.out and "(1 without a reference: not scored)" in cap.out
    assert "seq_a" not in cap.err
    for p in (garbage, truncated, unscored, missing):
        assert str(p) in cap.err, p
    assert f"FAILED {noref}" not in cap.err
    assert "no scored samples" in cap.err


def test_perturb_conditions_on_the_command_line(bags, tmp_path, capsys):
    out = tmp_path / "perturbed"
    args = [str(bags[0]), "-e", "madgwick", "-s", "as-recorded", "-p", "none", "-p", "rate:50+bias:random:1",
            "--out", str(out), "--no-plots", "-q"]
    assert main(args) == 0
    text = capsys.readouterr().out
    assert "perturbation" in text and "rate:50+bias:random:1" in text
    data = json.loads((out / "results.json").read_text())
    assert data["settings"]["perturbations"] == ["none", "rate:50+bias:random:1"]
    assert [r["perturbation"] for r in data["results"]] == ["none", "rate:50+bias:random:1"]
    drawn = data["sequences"][0]["perturbations"]["rate:50+bias:random:1"]["as-recorded"][1]["bias_dps"]
    assert len(drawn) == 3 and drawn != [0.0, 0.0, 0.0]
    assert "perturbation" in (out / "results.csv").read_text().splitlines()[0]
    assert main([str(bags[0]), "-p", "wobble:3"]) == 2
    assert "bad perturbation 'wobble:3'" in capsys.readouterr().err


def test_usage_errors_exit_2(bags, capsys):
    assert main([str(bags[0]), "--estimators", "riann,kalman"]) == 2
    assert "unknown estimator 'kalman'" in capsys.readouterr().err
    assert main([str(bags[0]), "--estimators", "madgwick:gain=1"]) == 2
    assert "unknown parameter 'gain'" in capsys.readouterr().err
    assert main([str(bags[0]), "--scenarios", "easy"]) == 2
    assert main([str(bags[0]), "--rates", "0"]) == 2


def test_rates_plot(bags, tmp_path):
    out = tmp_path / "rates"
    rc = main(
        [
            *map(str, bags),
            "--estimators",
            "madgwick",
            "--scenarios",
            "realistic",
            "--rates",
            "50,100",
            "--out",
            str(out),
            "-q",
        ]
    )
    assert rc == 0
    rows = json.loads((out / "results.json").read_text())["results"]
    # the requested rate, and the resampled stamps' own rate (within 1 / the sequence's length of it)
    assert sorted({r["rate"] for r in rows}) == [50.0, 100.0]
    assert all(abs(r["rate_hz"] / r["rate"] - 1.0) < 1e-3 for r in rows)
    assert (out / "rmse_vs_rate.png").is_file()


def test_write_estimates(bags, tmp_path):
    out = tmp_path / "est"
    rc = main(
        [
            str(bags[0]),
            "--estimators",
            "riann,madgwick:beta=0.1",
            "--scenarios",
            "realistic",
            "--write-estimates",
            str(out),
            "-q",
        ]
    )
    assert rc == 0
    dst = out / bags[0].name
    assert dst.exists()
    from rosbags.highlevel import AnyReader

    with AnyReader([dst]) as reader:
        topics = {c.topic: c.msgtype for c in reader.connections}
        counts = {c.topic: c.msgcount for c in reader.connections}
    t1 = topic_for("realistic", "madgwick(beta=0.1)")
    assert t1 == "/eval/realistic/madgwick_beta_0_1"
    assert topics[t1] == "geometry_msgs/msg/QuaternionStamped"
    assert topics["/eval/realistic/riann"] == "geometry_msgs/msg/QuaternionStamped"
    rec = bagio.read_recording(bags[0])
    assert counts[t1] == len(rec) - ev.summarise(ev.Source(bags[0], rec)).i0  # realistic: from the motion onset
    # the copy still holds the original recording
    rec2 = bagio.read_recording(dst)
    np.testing.assert_array_equal(rec2.stamps_ns, rec.stamps_ns)


def test_tune_adds_the_best_filter(bags, tmp_path, capsys):
    out = tmp_path / "tune"
    rc = main(
        [
            *map(str, bags),
            "--estimators",
            "madgwick",
            "--tune",
            "madgwick:beta=0.0/0.1",
            "--scenarios",
            "realistic",
            "--out",
            str(out),
            "--no-plots",
            "-q",
        ]
    )
    assert rc == 0
    data = json.loads((out / "results.json").read_text())
    assert data["tuning"][0]["best"]["params"] == {"beta": 0.1}
    assert "madgwick(beta=0.1) tuned" in capsys.readouterr().out


def test_live_rejects_parallel_jobs(bags, capsys):
    assert main([str(bags[0]), "--live", "--jobs", "2"]) == 2
    assert "one replay at a time" in capsys.readouterr().err


# -- BROAD acceptance ---------------------------------------------------------------------------------
ACCEPT_TRIALS = ("06", "07", "21")  # fast motions: the realistic scenario separates the estimators


def direct_onnx_rmse(rec) -> float:
    """RMSE of the published model run directly with ONNX Runtime over the realistic-scenario arrays."""
    import onnxruntime as ort

    srec, _ = ev.scenario_recording(rec, ev.REALISTIC, seed=0)
    sess = ort.InferenceSession(
        str(importlib.resources.files("riann") / "riann.onnx"), providers=["CPUExecutionProvider"]
    )
    dt = np.full((len(srec), 1), 1.0 / float(rec.meta.get("sampling_rate", rec.rate_hz)))
    x = np.concatenate([srec.acc, srec.gyr, dt], axis=1).astype(np.float32)[None]
    out = sess.run(["output"], {"input": x, "h0": np.zeros((2, 1, 1, 200), np.float32)})[0][0]
    return ev.score(srec, out.astype(np.float64)).rmse_deg


@pytest.mark.broad
@pytest.mark.slow
def test_broad_acceptance(broad_dir, tmp_path):
    files = [p for p in sorted(broad_dir.iterdir()) if p.name[:2] in ACCEPT_TRIALS and p.suffix in (".hdf5", ".mat")]
    assert len(files) == len(ACCEPT_TRIALS)
    have = ev.available_estimators()
    # without the gyro-bias front end and with one copy, the evaluator's RIANN at the native rate is the
    # published network
    specs = ["riann:gyro_bias_estimation=false:ensemble=1"] + [
        s for n, s in (("madgwick", "madgwick:beta=0.033"), ("mahony", "mahony:kp=1:ki=0.3")) if n in have
    ]
    out = tmp_path / "broad"
    rc = main(
        [
            *map(str, files),
            "--estimators",
            ",".join(specs),
            "--scenarios",
            "realistic",
            "--seed",
            "0",
            "--jobs",
            "2",
            "--out",
            str(out),
            "--no-plots",
            "-q",
        ]
    )
    assert rc == 0
    rows = json.loads((out / "results.json").read_text())["results"]
    riann = {r["sequence"]: r["rmse_deg"] for r in rows if r["estimator_name"] == "riann"}
    from riann_ros.datasets.broad import read_broad

    for f in files:
        rec = read_broad(f)
        assert riann[rec.name] == pytest.approx(direct_onnx_rmse(rec), abs=0.01), rec.name
    mean_riann = np.mean(list(riann.values()))
    for label in ("madgwick(beta=0.033)", "mahony(kp=1, ki=0.3)"):
        other = [r["rmse_deg"] for r in rows if r["estimator"] == label]
        if other:
            assert mean_riann < np.mean(other), label


# -- live ---------------------------------------------------------------------------------------------
@pytest.mark.ros
@pytest.mark.slow
def test_live_equals_offline(bags, tmp_path, monkeypatch, capsys):
    pytest.importorskip("rclpy")
    monkeypatch.setenv("ROS_AUTOMATIC_DISCOVERY_RANGE", "LOCALHOST")
    monkeypatch.setenv("ROS_DOMAIN_ID", "31")
    args = [
        str(bags[0]),
        "--estimators",
        "riann,madgwick:beta=0.1",
        "--scenarios",
        "restrictive,realistic",
        "--no-plots",
        "-q",
    ]
    assert main([*args, "--out", str(tmp_path / "off")]) == 0
    assert main([*args, "--out", str(tmp_path / "live"), "--live", "--speed", "0"]) == 0
    assert "messages lost / published: riann 0 /" in capsys.readouterr().out
    off = json.loads((tmp_path / "off" / "results.json").read_text())["results"]
    live = json.loads((tmp_path / "live" / "results.json").read_text())["results"]
    assert len(off) == len(live) == 4
    for a, b in zip(off, live, strict=True):
        assert (a["scenario"], a["estimator"]) == (b["scenario"], b["estimator"])
        assert b["mode"] == "live" and b["lost"] == 0
        assert abs(a["rmse_deg"] - b["rmse_deg"]) < 0.01, (a, b)
        # the σ comes from the covariance the node published on imu/data: the same scores as offline
        assert b["nees"] is not None and abs(a["nees"] - b["nees"]) < 0.01 * a["nees"], (a, b)
        assert abs(a["cover95_pct"] - b["cover95_pct"]) < 0.5, (a, b)


@pytest.mark.broad
@pytest.mark.slow
def test_broad_bag_scores_equal_file_scores(broad_dir, tmp_path):
    """A trial converted with riann-bag-convert scores exactly like the trial file read directly."""
    from riann_ros.cli.convert import main as convert_main

    src = next(p for p in sorted(broad_dir.iterdir()) if p.name.startswith("07_"))
    bag = tmp_path / "trial07.mcap"
    assert convert_main([str(src), "-o", str(bag), "-q"]) == 0
    outs = {}
    for name, inp in (("file", src), ("bag", bag)):
        out = tmp_path / name
        assert (
            main([str(inp), "--estimators", "riann,vqf", "--scenarios", "all", "--out", str(out), "--no-plots", "-q"])
            == 0
        )
        outs[name] = json.loads((out / "results.json").read_text())
    a, b = outs["file"]["results"], outs["bag"]["results"]
    assert [(r["scenario"], r["estimator"]) for r in a] == [(r["scenario"], r["estimator"]) for r in b]
    for ra, rb in zip(a, b, strict=True):
        assert ra["rmse_deg"] == pytest.approx(rb["rmse_deg"], abs=1e-9)
        assert ra["n_scored"] == rb["n_scored"]
    assert outs["file"]["sequences"][0]["scenarios"] == outs["bag"]["sequences"][0]["scenarios"]


@pytest.mark.slow
@pytest.mark.parametrize(("chunk", "t0_ns"), [(1000, 1_700_000_000_000_000_000), (257, 0)])
def test_streamed_bag_equals_whole_recording(tmp_path, chunk, t0_ns):
    """Bags are evaluated chunk by chunk (bounded memory): the same rows, scenario infos, plot series and estimates
    as the whole recording in one chunk, for all four estimators and all three scenarios, with small chunks (the
    initial rest crosses chunk boundaries with 257)."""
    rec = synthetic(rate=200.0, rest_s=3.0, move_s=12.0, name="streamed", t0_ns=t0_ns)
    bag = bagio.write_recording(tmp_path / "streamed.mcap", rec)
    settings = ev.EvalSettings(
        estimators=ev.parse_estimators("riann,madgwick,mahony,vqf"),
        scenarios=list(ev.SCENARIOS),
        seed=3,
        with_heading=True,
        series_for="*",
        series_step=7,
        keep_estimates=True,
        chunk=chunk,
        conditions=[ev.parse_condition("none"),
                    ev.parse_condition("jitter:10/20/30ms+dropout:0.1-0.6s@3s+bias:random:1")],
    )
    streamed = ev.evaluate_source(bag, settings)
    whole = ev.evaluate_source(bag, settings, recording=ev.load_recording(bag))
    assert streamed.error is None and whole.error is None
    assert (streamed.name, streamed.dataset, streamed.citation) == (whole.name, whole.dataset, whole.citation)
    assert streamed.scenarios == whole.scenarios
    assert len(streamed.rows) == len(whole.rows) == 4 * 4 * 2
    assert streamed.perturbations == whole.perturbations
    timing = {"seconds", "cpu_seconds"}
    for ra, rb in zip(streamed.rows, whole.rows, strict=True):
        a, b = ra.to_dict(), rb.to_dict()
        assert list(a) == list(b)  # same columns in the same order
        for key in ("rmse_deg", "max_err_deg", "heading_rmse_deg", "total_rmse_deg", "median_err_deg", "std_err_deg",
                    "heading_median_deg", "total_min_deg", "best_t_offset_rmse_deg"):
            if key in b:
                assert a[key] == pytest.approx(b[key], abs=1e-6), (a["scenario"], a["estimator"], key)
        assert a.get("best_t_offset_s") == pytest.approx(b.get("best_t_offset_s"), abs=1e-9)
        exact = timing | {"best_t_offset_s"}
        # the uncertainty's float sums (errors within round-off, added chunk by chunk in another order)
        sums = {"nees", "yaw_nees", "sigma_hist"}
        for key in ("nees", "yaw_nees"):
            assert (key in a) == (key in b) and a.get(key, 0.0) == pytest.approx(b.get(key, 0.0), rel=1e-4, abs=1e-6)
        if "sigma_hist" in a:
            assert sum(a["sigma_hist"]["n"]) == sum(b["sigma_hist"]["n"])
            assert sum(a["sigma_hist"]["e_deg"]) == pytest.approx(sum(b["sigma_hist"]["e_deg"]), rel=1e-4)
        assert {k: v for k, v in a.items() if k not in exact | sums and not k.endswith("_deg")} == {
            k: v for k, v in b.items() if k not in exact | sums and not k.endswith("_deg")
        }
    sa, sb = streamed.series, whole.series
    assert sa["sequence"] == sb["sequence"]
    for scn in settings.scenarios:
        np.testing.assert_array_equal(sa["t"][scn], sb["t"][scn])
        np.testing.assert_array_equal(sa["scored"][scn], sb["scored"][scn])
        for label, curve in sb["curves"][scn].items():
            np.testing.assert_allclose(sa["curves"][scn][label], curve, atol=1e-4, equal_nan=True)
    ea, eb = streamed.estimates, whole.estimates
    np.testing.assert_array_equal(ea["stamps"], eb["stamps"])
    for label, q in eb["quats"].items():
        np.testing.assert_allclose(ea["quats"][label], q, atol=1e-5)


def magnetometer_bag(tmp: Path, name: str, seed: int) -> Path:
    """A short 9D synthetic recording whose magnetometer carries a hard iron the online calibration learns."""
    rec = generate(rate=100.0, duration=10.0, seed=seed, name=name)
    rec.mag = distort(rec.quat_ref, np.array([25.0, -10.0, 15.0]) * 1e-6, noise_t=0.3e-6, seed=seed)
    return bagio.write_recording(tmp / f"{name}.mcap", rec)


@pytest.mark.ros
@pytest.mark.slow
def test_live_rows_do_not_depend_on_the_order_of_the_inputs(tmp_path, capsys):
    """--live restarts the nodes' estimators before each replay (~/restart): an input's rows are the same whether it
    is replayed first or after another that taught the online magnetometer calibration its hard iron (9D)."""
    pytest.importorskip("rclpy")
    a, b = magnetometer_bag(tmp_path, "mag_a", 1), magnetometer_bag(tmp_path, "mag_b", 2)
    args = ["--estimators", "riann,vqf", "--scenarios", "realistic", "--no-plots", "-q", "--live", "--speed", "0"]
    rows = {}
    for order in ((a, b), (b, a)):
        out = tmp_path / "_".join(p.stem for p in order)
        assert main([*map(str, order), *args, "--out", str(out)]) == 0
        rows[order[0].stem] = {(r["sequence"], r["estimator"]): r
                               for r in json.loads((out / "results.json").read_text())["results"]}
    first, second = rows["mag_a"], rows["mag_b"]
    assert sorted(first) == sorted(second) and len(first) == 4
    for key, r in first.items():
        s = second[key]
        assert r["sensors"] == "9D" and r["lost"] == 0 and s["lost"] == 0, (r, s)
        for field in ("rmse_deg", "max_err_deg", "heading_rmse_deg", "heading_max_deg", "total_rmse_deg", "nees",
                      "yaw_nees"):
            assert abs(r[field] - s[field]) < 1e-6, (key, field, r[field], s[field])
