"""The demo's real recording and `make demo`.

``bags/broad_21_undisturbed_fast_combined.mcap`` is one BROAD trial converted by ``riann-bag-convert`` (the one the
dataset's licence lets the repository ship): small enough, whole, zstd-compressed, carrying its attribution, readable
by ``rosbags`` and by the ``mcap`` package's own reader, and the trial file's samples exactly. ``make demo`` scores
it in every condition beside the synthetic bags, and the README shows what it writes.
"""

from __future__ import annotations

import json
import re
import shlex
import subprocess
import sys
from collections import Counter
from pathlib import Path

import numpy as np
import pytest
import results_tables as rt
import yaml

from conftest import ROOT, executable
from riann_ros import bagio
from riann_ros.bagio.layout import INFO_KEY, STRING_TYPE, typestore
from riann_ros.datasets.broad import read_broad

TRIAL = "21_undisturbed_fast_combined"
BAG = ROOT / "bags" / f"broad_{TRIAL}.mcap"
MAX_BYTES = 10_000_000  # the limit for the shipped trial
#: what CC BY 4.0 asks of the attribution: the creators, the source, the licence and its address
ATTRIBUTION = ("D. Laidig, M. Caruso, A. Cereatti, T. Seel", "BROAD — A Benchmark for Robust Inertial Orientation",
               "https://doi.org/10.3390/data6070072", "CC BY 4.0", "https://creativecommons.org/licenses/by/4.0/")
FIGURE = re.compile(r"\d+\.\d+")


@pytest.fixture(scope="module")
def real():
    return bagio.read_recording(BAG)


def test_the_real_bag_is_small_compressed_and_carries_the_attribution():
    from rosbags.rosbag2 import Reader

    assert BAG.stat().st_size <= MAX_BYTES
    assert bagio.bag_storage(BAG) == "mcap" and bagio.bag_compression(BAG) == "zstd"
    info = bagio.read_info(BAG)
    assert (info["name"], info["dataset"], info["has_reference"], info["has_mag"]) == (TRIAL, "broad", True, True)
    with Reader(BAG) as reader:  # rosbags, without the project's reader
        counts = {c.topic: c.msgcount for c in reader.connections}
    assert counts[bagio.IMU_TOPIC] == counts[bagio.MAG_TOPIC] == info["samples"]
    readme = " ".join((ROOT / "bags" / "README.md").read_text().replace("\n>", " ").split())  # quote lines joined
    for part in ATTRIBUTION:
        assert part in info["source"], part
        assert part in readme, part


@pytest.mark.slow
def test_the_real_bag_is_a_whole_regular_stream(real):
    # the trial at its own rate from its first sample: one constant step (2000/7 Hz = 3.5 ms), nothing resampled
    # or cut out
    assert real.name == TRIAL and len(real) == bagio.read_info(BAG)["samples"]
    assert real.stamps_ns[0] == 0 and np.all(np.diff(real.stamps_ns) == 3_500_000)
    assert real.mag is not None and np.isfinite(real.mag).all()
    assert real.quat_ref is not None and 0.9 < np.isfinite(real.quat_ref[:, 0]).mean() < 1.0  # markers lost: none
    assert 0 < real.score_mask.sum() < len(real)  # rests at both ends are not scored


@pytest.mark.slow
def test_the_real_bag_reads_with_rosbags(real):
    from rosbags.rosbag2 import Reader

    with Reader(BAG) as reader:
        counts = {c.topic: c.msgcount for c in reader.connections}
        info_conn = [c for c in reader.connections if c.topic == bagio.INFO_TOPIC]
        (raw,) = [raw for _, _, raw in reader.messages(connections=info_conn)]
        imu_conn = [c for c in reader.connections if c.topic == bagio.IMU_TOPIC]
        last = None
        for _, t, msg in reader.messages(connections=imu_conn):
            last = (t, msg)
    assert counts[bagio.REF_TOPIC] == int(np.isfinite(real.quat_ref[:, 0]).sum())
    assert json.loads(typestore().deserialize_cdr(raw, STRING_TYPE).data) == bagio.read_info(BAG)
    assert last is not None and last[0] == real.stamps_ns[-1]
    acc = typestore().deserialize_cdr(last[1], bagio.IMU_TYPE).linear_acceleration
    assert np.array_equal([acc.x, acc.y, acc.z], real.acc[-1])


@pytest.mark.slow
def test_the_real_bag_reads_with_the_mcap_package(real):
    """The mcap package's own reader (CRCs checked, zstd chunks decompressed): every message the summary counts,
    the IMU samples those rosbags reads, and the info in the rosbag2 metadata record."""
    from mcap.reader import make_reader

    with BAG.open("rb") as f:
        reader = make_reader(f, validate_crcs=True)
        assert reader.get_header().profile == "ros2"
        summary = reader.get_summary()
        assert summary is not None and {c.compression for c in summary.chunk_indexes} == {"zstd"}
        counts: Counter[str] = Counter()
        imu, info_raw = [], None
        for _, channel, message in reader.iter_messages(log_time_order=True):
            counts[channel.topic] += 1
            if channel.topic == bagio.IMU_TOPIC and counts[channel.topic] % 997 == 1:
                imu.append((message.log_time, message.data))
            elif channel.topic == bagio.INFO_TOPIC:
                info_raw = message.data
        records = {m.name: m.metadata for m in reader.iter_metadata()}
    stats = summary.statistics
    assert stats is not None
    assert counts == {summary.channels[c].topic: n for c, n in stats.channel_message_counts.items()}
    for t, data in imu:
        msg = typestore().deserialize_cdr(data, bagio.IMU_TYPE)
        k = int(np.searchsorted(real.stamps_ns, t))
        assert real.stamps_ns[k] == t == msg.header.stamp.sec * 10**9 + msg.header.stamp.nanosec
        v = msg.angular_velocity
        assert np.array_equal([v.x, v.y, v.z], real.gyr[k])
    rosbag2 = yaml.safe_load(records["rosbag2"]["serialized_metadata"])
    assert rosbag2["message_count"] == sum(counts.values())
    assert info_raw is not None
    info = json.loads(typestore().deserialize_cdr(info_raw, STRING_TYPE).data)
    assert json.loads(rosbag2["custom_data"][INFO_KEY]) == info == bagio.read_info(BAG)


def _same_samples(a, b) -> None:
    """Exactly the same samples (stored float64 values: no tolerance), NaN where the reference is missing."""
    for field in ("stamps_ns", "acc", "gyr", "quat_ref", "mag", "score_mask"):
        nan = field in ("quat_ref", "mag")
        assert np.array_equal(getattr(a, field), getattr(b, field), equal_nan=nan), field


@pytest.mark.broad
@pytest.mark.slow
def test_the_real_bag_is_the_trial_file_converted_by_make_bags(real, broad_dir: Path, tmp_path: Path):
    """The bag holds the trial file's samples exactly, and the command in make_bags.sh writes it again."""
    [line] = [s for s in (ROOT / "bags" / "make_bags.sh").read_text().splitlines()
              if s.startswith("$CONVERT") and BAG.name in s]
    argv = shlex.split(line.replace("$BROAD", str(broad_dir)))[1:]
    src = Path(argv[0])
    trial = read_broad(src)
    _same_samples(real, trial)
    assert (real.name, real.source, real.meta) == (trial.name, trial.source, trial.meta)
    i = argv.index("-o")
    out = tmp_path / BAG.name
    run = subprocess.run([str(executable("riann-bag-convert")), *argv[:i], *argv[i + 2:], "-o", str(out), "-q"],
                         capture_output=True, text=True)
    assert run.returncode == 0, run.stderr
    again = bagio.read_recording(out)
    _same_samples(again, real)
    assert bagio.read_info(out) == bagio.read_info(BAG)
    assert bagio.bag_compression(out) == "zstd"


def _block(text: str, name: str) -> str:
    [body] = [m["body"] for m in rt.MARKER.finditer(text) if m["name"] == name]
    return body.strip()


def _same_figures(shown: str, fresh: str) -> None:
    """The same table, its figures equal to the last printed digit (± 0.01: a value on a rounding boundary may print
    either way on another CPU)."""
    assert FIGURE.sub("#", shown) == FIGURE.sub("#", fresh), (shown, fresh)
    a, b = (np.array([float(x) for x in FIGURE.findall(s)]) for s in (shown, fresh))
    assert len(a) == len(b) > 0 and np.abs(a - b).max() <= 0.0101, (shown, fresh)


@pytest.mark.slow
def test_make_demo_scores_the_real_trial_and_the_readme_shows_what_it_writes(tmp_path: Path):
    out = tmp_path / "demo_out"
    venv_bin = Path(sys.executable).parent
    # the Makefile's demo target itself, into a folder of its own, with this session's installation (-o: no setup)
    run = subprocess.run(["make", "-s", "-o", f"{venv_bin}/.installed", "demo", f"BIN={venv_bin}", f"DEMO_OUT={out}"],
                         cwd=ROOT, capture_output=True, text=True, timeout=1200)
    assert run.returncode == 0, run.stdout[-2000:] + run.stderr[-4000:]
    rows = rt.run_rows(out / "results.json")
    real = rows.where(sequence=TRIAL)
    assert {(r["perturbation"], r["estimator"]) for r in real.rows} == {
        (c, e) for c in rt.DEMO_CONDITIONS for e in rt.DEMO_ESTIMATORS}
    assert {r["sensors"] for r in rows.rows} == {"6D"}
    assert all(np.isfinite(r["rmse_deg"]) and r["n_scored"] > 0 for r in real.rows)
    plots = sorted(p.name for p in out.glob(f"roll_pitch_{TRIAL}*.png"))
    assert len(plots) == len(rt.DEMO_CONDITIONS) and all((out / p).stat().st_size > 0 for p in plots), plots
    assert "Laidig" in (out / "report.md").read_text()
    readme = (ROOT / "README.md").read_text()
    _same_figures(_block(readme, "readme-demo-real"), rt.demo_real(rows))
    _same_figures(_block(readme, "readme-demo-synthetic"), rt.demo_synthetic(rows))
