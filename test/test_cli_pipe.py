"""stdout that goes quiet when its reader leaves (riann_ros.cli.pipe): ``riann-bag-eval … | head`` still writes its
result files and exits 0, with no traceback."""

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
