"""riann-mag-calibrate under the faults users cause (issue 48): outputs checked before any work, nothing written on
exit status 1, no traceback for any input (a prior with a huge covariance, a read-only plots folder, …), messages
that name the target, never a temporary file."""

from __future__ import annotations

import subprocess
from pathlib import Path

import numpy as np
import pytest
from helpers_fs import read_only

from conftest import executable
from riann_ros import bagio
from riann_ros.cli import magcal
from riann_ros.datasets.synthetic import generate
from riann_ros.magcal.records import IDENTITY_9, MagCalibration
from riann_ros.magcal.store import to_yaml
from riann_ros.magcal.synthetic import distort

UT = 1e-6


@pytest.fixture(scope="module")
def bag(tmp_path_factory) -> Path:
    """Rotation with a distorted magnetometer: something to calibrate from."""
    rec = generate(duration=40.0, rate=100, motion="rotation", seed=2)
    rec.mag = distort(rec.quat_ref, np.array([20.0, -10.0, 5.0]) * UT, noise_t=0.3e-6, seed=2)
    return bagio.write_recording(tmp_path_factory.mktemp("magcal") / "robot.mcap", rec)


def run(*argv: str | Path) -> subprocess.CompletedProcess:
    return subprocess.run([str(executable("riann-mag-calibrate")), *map(str, argv)], capture_output=True, text=True,
                          timeout=300)


def one_line(r: subprocess.CompletedProcess, status: int, *words: str) -> str:
    """The run ended with ``status`` and a single stderr line naming every one of ``words``, no traceback."""
    assert r.returncode == status, r.stdout + r.stderr
    assert "Traceback" not in r.stderr and ".tmp" not in r.stderr, r.stderr
    lines = r.stderr.strip().splitlines()
    assert len(lines) == 1 and all(w in lines[0] for w in words), r.stderr
    return lines[0]


def files(folder: Path) -> list[str]:
    return sorted(str(p.relative_to(folder)) for p in folder.rglob("*"))


def test_a_read_only_plots_folder_is_refused_before_the_fit_and_nothing_written(bag, tmp_path):
    with read_only(tmp_path / "plots") as plots:
        r = run(bag, "--out", tmp_path / "my_mag.yaml", "--plots", plots)
        one_line(r, 2, "--plots", str(plots), "cannot write into")
    assert files(tmp_path) == ["plots"] and "recording:" not in r.stdout  # no fit ran


def test_an_out_folder_that_cannot_be_made_is_refused_before_the_fit(bag, tmp_path):
    with read_only(tmp_path / "locked") as locked:
        target = locked / "sub" / "my_mag.yaml"
        one_line(run(bag, "--out", target), 2, "--out", str(target), "cannot write into", str(locked))
        assert files(locked) == []


@pytest.mark.parametrize("where", ["out", "figure"])
def test_a_folder_in_the_place_of_an_output_is_refused(bag, tmp_path, where):
    out = tmp_path / "my_mag.yaml"
    (out if where == "out" else tmp_path / "my_mag_sphere.png").mkdir()
    r = run(bag, "--out", out, "--force")
    one_line(r, 2, str(out) if where == "out" else str(tmp_path / "my_mag_sphere.png"))


@pytest.mark.parametrize("hard_sd_t", [1e150, 7e-4])
def test_a_prior_with_a_huge_covariance_is_one_line_and_nothing_written(bag, tmp_path, hard_sd_t):
    """A σ of 1e150 (no number a calibration can mean: refused by the validation every calibration file gets) and a
    hard-iron σ of 700 µT (a calibration, but too wide to start a fit from): one line each, nothing written."""
    prior = tmp_path / "huge.yaml"  # (written as text: the package never saves a calibration it would refuse)
    prior.write_text(to_yaml(MagCalibration(
        hard_iron_t=(0.0, 0.0, 0.0), soft_iron=IDENTITY_9,
        covariance=tuple(np.diag([1e-6] * 9 + [hard_sd_t ** 2] * 3).ravel()),
        state="converging", windows=3, converged_after_s=None, soft_iron_model="full")))
    out = tmp_path / "out" / "my_mag.yaml"
    r = run(bag, "--prior", prior, "--out", out)
    one_line(r, 1, str(prior), "over its bound" if hard_sd_t > 1.0 else "too wide to start from", "--prior")
    assert "Warning" not in r.stderr and not (tmp_path / "out").exists()


def test_nothing_to_calibrate_from_writes_nothing_not_even_the_plots_folder(tmp_path):
    still = bagio.write_recording(tmp_path / "no_mag.mcap", generate(duration=10.0, rate=100, seed=1))
    r = run(still, "--out", tmp_path / "cal" / "my_mag.yaml", "--plots", tmp_path / "figs")
    one_line(r, 1, str(still), "no magnetometer", "nothing written")
    assert files(tmp_path) == ["no_mag.mcap"]


def test_an_output_that_fails_after_the_fit_leaves_nothing_and_names_its_target(bag, tmp_path, capsys):
    """The folder of the figures becomes read-only while the fit runs (checked writable before it): the run ends
    with one line naming the figure, and neither the calibration nor a figure nor a temporary file is left."""
    plots, out = tmp_path / "plots", tmp_path / "cal" / "my_mag.yaml"
    plots.mkdir()
    args = magcal.build_parser().parse_args([str(bag), "--out", str(out), "--plots", str(plots)])
    magcal._check_outputs(args)
    rf = magcal._fit(args)
    with read_only(plots):
        with pytest.raises(magcal._Failed) as failed:
            magcal._write(args, rf)
    text = str(failed.value)
    assert text.startswith(f"cannot write {plots / 'my_mag_sphere.png'}: ") and text.endswith("; nothing written")
    assert ".tmp" not in text
    assert files(tmp_path) == ["plots"]  # the calibration's folder made for it is gone again
    magcal._write(args, rf)  # writable again: everything
    assert files(tmp_path) == ["cal", "cal/my_mag.yaml", "plots", "plots/my_mag_heading.png",
                               "plots/my_mag_sphere.png"]
