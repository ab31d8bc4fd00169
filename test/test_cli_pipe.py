"""stdout and stderr that go quiet when their reader leaves (riann_ros.cli.pipe): ``riann-bag-eval … | head`` still
writes its result files and exits 0, with no traceback."""

from __future__ import annotations

from pathlib import Path

import pytest
from test_evaluation import synthetic

bagio = pytest.importorskip("riann_ros.bagio")


@pytest.fixture(scope="module")
def bag(tmp_path_factory) -> Path:
    rec = synthetic(name="seq", t0_ns=1_700_000_000_000_000_000)
    return bagio.write_recording(tmp_path_factory.mktemp("files") / "seq.mcap", rec)


def test_a_reader_that_leaves_early_costs_no_results(bag, tmp_path):
    """``riann-bag-eval … | head``: the reader closes stdout before the tables are printed; the run still writes its
    result files and exits 0, with no traceback."""
    import os
    import subprocess
    import sys

    out = tmp_path / "piped"
    root = Path(__file__).resolve().parents[1]
    env = {**os.environ, "PYTHONPATH": os.pathsep.join([str(root), os.environ.get("PYTHONPATH", "")])}
    proc = subprocess.Popen([sys.executable, "-m", "riann_ros.cli.evaluate", str(bag), "-e", "madgwick", "-s",
                             "as-recorded", "--no-plots", "--out", str(out)], stdout=subprocess.PIPE,
                            stderr=subprocess.PIPE, cwd=tmp_path, env=env)
    assert proc.stdout is not None and proc.stderr is not None
    proc.stdout.close()  # what `head` does once it has its lines (here: before any)
    err = proc.stderr.read().decode()
    assert proc.wait(timeout=120) == 0, err
    assert "Traceback" not in err and "BrokenPipe" not in err
    assert (out / "results.json").is_file() and (out / "report.md").is_file()


def test_a_reader_of_both_streams_that_leaves_early_costs_no_files(bag, tmp_path):
    """``riann-bag-eval … 2>&1 | head``: stderr's reader is gone too when the written files are reported there; the
    bag copy, the trajectory files and the result files are all still written."""
    import os
    import subprocess
    import sys

    out, est = tmp_path / "piped", tmp_path / "est"
    root = Path(__file__).resolve().parents[1]
    env = {**os.environ, "PYTHONPATH": os.pathsep.join([str(root), os.environ.get("PYTHONPATH", "")])}
    proc = subprocess.Popen([sys.executable, "-m", "riann_ros.cli.evaluate", str(bag), "-e", "madgwick", "-s",
                             "as-recorded", "--no-plots", "--out", str(out), "--write-estimates", str(est), "-q"],
                            stdout=subprocess.PIPE, stderr=subprocess.STDOUT, cwd=tmp_path, env=env)
    assert proc.stdout is not None
    proc.stdout.close()
    assert proc.wait(timeout=120) == 0
    assert (est / "seq.mcap").is_file() and (est / "seq.as-recorded.madgwick.tum").is_file()
    assert (est / "seq.as-recorded.reference.tum").is_file() and (out / "results.json").is_file()
