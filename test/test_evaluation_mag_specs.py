"""A saved magnetometer calibration scored offline: estimator specs that carry ``mag_calibration_file``,
``mag_hard_iron`` and ``mag_soft_iron`` (riann_ros.evaluation.specs), applied to each stream as the node applies them
at start (riann_ros.evaluation.runners), through ``riann-bag-eval``."""

from __future__ import annotations

import json
import re
from pathlib import Path

import numpy as np
import pytest

from riann_ros import bagio
from riann_ros import evaluation as ev
from riann_ros.cli.evaluate import main
from riann_ros.datasets.synthetic import generate
from riann_ros.evaluation.runners import OfflineRunner
from riann_ros.gate import GateConfig
from riann_ros.magcal.input import UseMag
from riann_ros.magcal.records import IDENTITY_9, MagCalibration, MagCalPrior
from riann_ros.magcal.store import save_calibration
from riann_ros.magcal.synthetic import distort

HARD_IRON_T = (25e-6, -10e-6, 15e-6)
SOFT = (1.05, 0.02, 0.0, 0.02, 0.95, 0.0, 0.0, 0.0, 1.0)


def calibration(hard: tuple[float, ...] = HARD_IRON_T, soft: tuple[float, ...] = IDENTITY_9) -> MagCalibration:
    cov = np.diag([1e-6] * 9 + [(0.5e-6) ** 2] * 3).reshape(-1)
    return MagCalibration(hard_iron_t=hard, soft_iron=soft, covariance=tuple(cov), state="calibrated",  # type: ignore[arg-type]
                          windows=200, converged_after_s=12.0, soft_iron_model="full")


@pytest.fixture
def cal_file(tmp_path: Path) -> Path:
    return save_calibration(tmp_path / "my_mag.yaml", calibration())


def distorted_recording(seconds: float = 30.0):
    """Synthetic motion whose magnetometer carries the hard iron HARD_IRON_T (what the file undoes)."""
    rec = generate(rate=100.0, duration=seconds, seed=3, name="distorted")
    rec.mag = distort(rec.quat_ref, np.asarray(HARD_IRON_T), noise_t=0.3e-6, seed=3)
    return rec


def test_spec_parses_mag_params_labels_and_records_them(cal_file, monkeypatch):
    monkeypatch.chdir(cal_file.parent)
    spec = ev.parse_estimator("riann:mag_calibration_file=my_mag.yaml")
    assert spec.label == "riann(mag_calibration_file=my_mag.yaml)" and spec.kwargs == {}
    assert spec.calibration == calibration()
    assert spec.node_params == {"mag_calibration_file": str(cal_file.resolve())}
    d = spec.to_dict()
    assert d["mag_params"] == {"mag_calibration_file": "my_mag.yaml"}
    assert d["mag_calibration_loaded"]["mag_hard_iron"] == list(HARD_IRON_T)
    assert d["mag_calibration_loaded"]["state"] == "calibrated"
    vqf = ev.parse_estimators("vqf:mag_hard_iron=20e-6/0/-10e-6:tau_acc=2,madgwick:mag_soft_iron=" +
                              "/".join(f"{v:g}" for v in SOFT))
    assert [s.label for s in vqf] == ["vqf(tau_acc=2, mag_hard_iron=2e-05/0/-1e-05)",  # the estimator's first
                                      "madgwick(mag_soft_iron=1.05/0.02/0/0.02/0.95/0/0/0/1)"]
    assert vqf[0].kwargs == {"tau_acc": 2.0} and vqf[0].mag_prior is None
    cfg = vqf[0].mag_config("false")
    assert cfg.mag_hard_iron == (20e-6, 0.0, -10e-6) and cfg.use_mag is UseMag.FALSE
    assert vqf[1].mag_config().mag_soft_iron == SOFT
    assert ev.parse_estimator("vqf").to_dict() == {"label": "vqf", "name": "vqf", "params": {}}


def test_the_files_calibration_replaces_the_parameters_and_is_the_prior(cal_file):
    """As the node at start: the file's hard and soft iron replace mag_hard_iron / mag_soft_iron, and its estimate
    with its covariance is where the online calibration starts."""
    spec = ev.parse_estimator(f"riann:mag_hard_iron=1e-6/2e-6/3e-6:mag_calibration_file={cal_file}")
    cfg = spec.mag_config()
    assert cfg.mag_hard_iron == HARD_IRON_T and cfg.mag_soft_iron == IDENTITY_9
    assert spec.mag_prior == MagCalPrior.from_calibration(calibration())
    plain = ev.parse_estimator("riann:mag_hard_iron=1e-6/2e-6/3e-6")
    run = OfflineRunner().start([spec, plain], GateConfig.for_rate(100.0))
    with_file, with_params = run.streams  # type: ignore[attr-defined]
    assert with_file.mag_prior == MagCalPrior.from_calibration(calibration())  # its covariance + a new run's doubt
    assert with_file.mag.config.mag_hard_iron == HARD_IRON_T
    assert with_params.mag_prior == MagCalPrior(hard_iron_t=(1e-6, 2e-6, 3e-6))


def test_a_saved_calibration_is_scored_offline(cal_file):
    """The heading with the file that undoes the recording's hard iron is better than without it (calibration on
    and off); with the calibration off the file gives what the same values as parameters give."""
    f = str(cal_file)
    specs = ev.parse_estimators(f"riann,riann:mag_calibration_file={f},vqf:mag_calibration=false,"
                                f"vqf:mag_calibration=false:mag_calibration_file={f},"
                                "vqf:mag_calibration=false:mag_hard_iron=25e-6/-10e-6/15e-6")
    settings = ev.EvalSettings(estimators=specs, scenarios=[ev.AS_RECORDED])
    res = ev.evaluate_source("distorted.mcap", settings, recording=distorted_recording())
    assert res.error is None
    h = {r.estimator: r.score.heading_rmse_deg for r in res.rows}
    assert all(r.sensors == "9D" for r in res.rows)
    assert h[f"riann(mag_calibration_file={f})"] < 1.0 < 3.0 < h["riann"]
    assert h[f"vqf(mag_calibration=False, mag_calibration_file={f})"] < 1.0 < 5.0 < h["vqf(mag_calibration=False)"]
    assert h[f"vqf(mag_calibration=False, mag_calibration_file={f})"] == \
        h["vqf(mag_calibration=False, mag_hard_iron=2.5e-05/-1e-05/1.5e-05)"]


@pytest.mark.parametrize("text, match", [
    ("riann:mag_calibration_file=missing.yaml", "mag_calibration_file missing.yaml does not exist"),
    ("riann:mag_calibration_file=.", "mag_calibration_file . is not a regular file"),
    ("riann:mag_calibration_file=", "needs a file"),
    ("vqf:mag_hard_iron=20e-6/0", "mag_hard_iron must be 3 numbers between '/'"),
    ("vqf:mag_hard_iron=a/0/0", "mag_hard_iron must be 3 numbers between '/'"),
    ("vqf:mag_hard_iron=2/0/0", "mag_hard_iron=2 is above its maximum 1"),
    ("vqf:mag_soft_iron=1/0/0", "mag_soft_iron must be 9 numbers between '/'"),
    ("vqf:mag_hard_iron=20e-6,0,-10e-6", "must be 3 numbers between '/'"),
    ("vqf,0", "'0' is no estimator spec: in a spec a vector's numbers are written between '/'"),
    ("vqf:mag_hard_irn=0/0/0", "unknown parameter 'mag_hard_irn' for vqf; known: .*mag_calibration_file"),
])
def test_bad_mag_specs_are_refused_at_parse_time(text, match, tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    with pytest.raises(ValueError, match=match):
        ev.parse_estimators(text)


def test_a_file_that_is_no_calibration_is_refused_naming_it(tmp_path):
    params = tmp_path / "params.yaml"
    params.write_text("riann_node:\n  ros__parameters:\n    beta: 0.1\n")
    with pytest.raises(ValueError, match=re.escape(f"mag_calibration_file refused: {params}")):
        ev.parse_estimator(f"riann:mag_calibration_file={params}")
    reflection = save_calibration(tmp_path / "bad.yaml", calibration())
    identity = "mag_soft_iron: [1.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 1.0]"
    reflection.write_text(reflection.read_text().replace(identity, identity.replace("[1.0", "[-1.0")))
    with pytest.raises(ValueError, match=re.escape(f"mag_calibration_file refused: {reflection}")):
        ev.parse_estimator(f"vqf:mag_calibration_file={reflection}")


def test_command_line_scores_a_saved_calibration_and_records_it(cal_file, tmp_path, capsys):
    rec = distorted_recording(20.0)
    bag = bagio.write_recording(tmp_path / "distorted.mcap", rec)
    out = tmp_path / "eval"
    spec = f"vqf:mag_calibration=false:mag_calibration_file={cal_file}"
    assert main([str(bag), "-e", f"vqf:mag_calibration=false,{spec}", "-s", "as-recorded", "--no-plots", "-q",
                 "--out", str(out)]) == 0
    data = json.loads((out / "results.json").read_text())
    label = f"vqf(mag_calibration=False, mag_calibration_file={cal_file})"
    rows = {r["estimator"]: r for r in data["results"]}
    assert rows[label]["heading_rmse_deg"] < 1.0 < 5.0 < rows["vqf(mag_calibration=False)"]["heading_rmse_deg"]
    recorded = {e["label"]: e for e in data["settings"]["estimators"]}[label]
    assert recorded["mag_params"] == {"mag_calibration_file": str(cal_file)}
    assert recorded["mag_calibration_loaded"]["mag_hard_iron"] == list(HARD_IRON_T)
    assert main([str(bag), "-e", "riann:mag_calibration_file=nowhere.yaml", "--no-plots", "-q"]) == 2
    assert "mag_calibration_file nowhere.yaml does not exist" in capsys.readouterr().err


@pytest.mark.ros
@pytest.mark.slow
def test_live_nodes_get_the_mag_params(cal_file, tmp_path, monkeypatch):
    """--live passes a spec's mag_calibration_file (absolute) and mag_hard_iron to its node as parameters: the
    node's heading is the offline one."""
    pytest.importorskip("rclpy")
    bag = bagio.write_recording(tmp_path / "distorted.mcap", distorted_recording(20.0))
    monkeypatch.chdir(cal_file.parent)
    args = [str(bag), "-e", "vqf:mag_calibration=false:mag_calibration_file=my_mag.yaml,"
            "riann:mag_hard_iron=25e-6/-10e-6/15e-6", "-s", "as-recorded", "--no-plots", "-q"]
    assert main([*args, "--out", str(tmp_path / "off")]) == 0
    assert main([*args, "--out", str(tmp_path / "live"), "--live", "--speed", "0"]) == 0
    off = json.loads((tmp_path / "off" / "results.json").read_text())["results"]
    live = json.loads((tmp_path / "live" / "results.json").read_text())["results"]
    assert len(off) == len(live) == 2
    for a, b in zip(off, live, strict=True):
        assert a["estimator"] == b["estimator"] and b["mode"] == "live" and b["lost"] == 0
        assert a["heading_rmse_deg"] < 1.0 and abs(a["heading_rmse_deg"] - b["heading_rmse_deg"]) < 0.01, (a, b)
