"""A run over many inputs (riann_ros.evaluation.fleet): 1 000 inputs listed in a file (--inputs-from) on a local Dask
cluster, with the client's memory bounded by the per-input summaries (its peak resident set measured by the operating
system) and a progress bar with counts and ETA. ``make test`` runs it with 100 inputs (more than the cluster
executor keeps in flight, dask_cluster.MIN_WINDOW); the 1 000 (minutes on 2 shared cores) are marked ``scale``:
``make test-scale``."""

from __future__ import annotations

import csv
import os
import subprocess
import sys
import time

import pytest

# the CLI's main in a process of its own that writes its own peak resident set (VmHWM) to a file: the client's
# memory, the local cluster's scheduler included, the worker processes not
from bench_cluster import CLIENT

from riann_ros import bagio
from riann_ros.datasets.synthetic import generate
from riann_ros.evaluation import dask_cluster, store

pytest.importorskip("distributed")

CLIENT_LIMIT_MB = 500


@pytest.mark.slow
@pytest.mark.parametrize("n_inputs", [100, pytest.param(1000, marks=pytest.mark.scale)])
def test_listed_inputs_on_a_cluster_with_bounded_client_memory_and_progress(tmp_path, n_inputs):
    assert n_inputs > dask_cluster.MIN_WINDOW  # inputs wait for a place on the cluster
    tiny = bagio.write_recording(tmp_path / "tiny.mcap", generate(rate=100, duration=10, seed=1, start_s=1.0))
    corpus = tmp_path / "corpus"
    corpus.mkdir()
    names = [f"robot{k % 7}_{k:04d}.mcap" for k in range(n_inputs)]
    for name in names:
        (corpus / name).hardlink_to(tiny)  # files of their own paths (links to one file are one input)
    listing = corpus / "fleet.txt"
    listing.write_text("# the fleet's recordings, one a line\n\n" + "\n".join(names) + "\n")
    out, peak, err = tmp_path / "out", tmp_path / "peak_kb", tmp_path / "stderr.txt"
    t0 = time.monotonic()
    r = subprocess.run([sys.executable, "-c", CLIENT, str(peak), "--inputs-from", str(listing), "-e", "madgwick",
                        "-s", "as-recorded", "--offset-steps", "0", "--scheduler", "local:2", "--out", str(out)],
                       stdout=subprocess.PIPE, stderr=err.open("w"), text=True, timeout=1800, env=os.environ.copy())
    wall = time.monotonic() - t0
    text = err.read_text()
    assert r.returncode == 0, text[-3000:]
    peak_mb = int(peak.read_text()) / 1024
    print(f"{n_inputs} inputs on local:2: {wall:.0f} s wall, client peak RSS {peak_mb:.0f} MB")
    assert peak_mb < CLIENT_LIMIT_MB
    assert f"{n_inputs}/{n_inputs}" in text and "ETA" in text  # the bar's counts and time left, line by line
    assert "Dask cluster local: 2 worker(s)" in text
    with open(out / "results.csv") as f:
        assert sum(1 for _ in csv.DictReader(f)) == n_inputs
    assert len(list((out / store.SHARDS).glob(f"*{store.SUFFIX}"))) == n_inputs
    assert f"{n_inputs} of {n_inputs} input(s) evaluated" in r.stdout
