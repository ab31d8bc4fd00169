"""Bags cut off by a crash (riann_ros.bagio.repair), MCAP and sqlite3 cut with a byte slice: riann-bag-eval says what
is readable and how to go on, --salvage scores the readable part, riann-bag-convert --repair writes a complete bag of
the same messages."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest
from test_evaluation import synthetic

from riann_ros.cli.convert import main as convert_main
from riann_ros.cli.evaluate import main
from riann_ros.recording import Recording

bagio = pytest.importorskip("riann_ros.bagio")

T0 = 1_700_000_000_000_000_000


def _rows(out: Path) -> dict[str, dict]:
    return {r["estimator"]: r for r in json.loads((out / "results.json").read_text())["results"]}


@pytest.fixture(scope="module")
def long_rec() -> Recording:
    return synthetic(name="long", move_s=40.0, t0_ns=T0)  # 4,200 samples: an MCAP file of several chunks


def _cut(src: Path, dst: Path, fraction: float) -> Path:
    data = src.read_bytes()
    dst.write_bytes(data[: int(len(data) * fraction)])  # head -c N src > dst
    return dst


def _imu_count(err: str) -> int:
    """The readable IMU messages a message reports ('2,346 /imu/data_raw')."""
    word = next(w for w in err.replace("(", " ").split(", ") if w.endswith(" /imu/data_raw"))
    return int(word.split()[-2].replace(",", ""))


@pytest.mark.slow
def test_truncated_mcap(long_rec, tmp_path, capsys):
    whole = bagio.write_recording(tmp_path / "long.mcap", long_rec)
    cut = _cut(whole, tmp_path / "cut.mcap", 0.6)
    args = ["-e", "madgwick", "-s", "as-recorded", "--no-plots", "--offset-steps", "0"]
    assert main([str(cut), *args, "-q"]) == 1
    err = capsys.readouterr().err
    assert "truncated" in err and f"ends at byte {cut.stat().st_size:,}" in err and "of 4,200 IMU samples" in err
    assert "--salvage" in err and f"riann-bag-convert --repair {cut} -o {tmp_path / 'cut_repaired.mcap'}" in err
    n = _imu_count(err)
    assert 1000 < n < 4200 * 0.6
    # --salvage: the readable part is scored, with a warning and the counts in results.json
    out = tmp_path / "salvaged"
    assert main([str(cut), *args, "--salvage", "--out", str(out), "-q"]) == 0
    assert "salvaged: truncated" in capsys.readouterr().err
    data = json.loads((out / "results.json").read_text())
    (seq,) = data["sequences"]
    assert seq["salvaged"]["messages_per_topic"]["/imu/data_raw"] == n
    assert seq["salvaged"]["imu_samples_recorded"] == 4200 and seq["salvaged"]["file_bytes"] == cut.stat().st_size
    (row,) = data["results"]
    assert row["n_samples"] == n and row["source"] == str(cut)
    # riann-bag-convert --repair: a complete bag of the same messages; the output is never overwritten silently
    fixed = tmp_path / "fixed.mcap"
    assert convert_main(["--repair", str(cut), "-o", str(fixed)]) == 0
    assert f"{n:,} /imu/data_raw" in capsys.readouterr().err
    rec = bagio.read_recording(fixed)
    assert len(rec) == n
    np.testing.assert_array_equal(rec.stamps_ns, long_rec.stamps_ns[:n])
    np.testing.assert_allclose(rec.gyr, long_rec.gyr[:n], atol=1e-12)
    before = fixed.read_bytes()
    assert convert_main(["--repair", str(cut), "-o", str(fixed)]) == 1
    assert "exists" in capsys.readouterr().err and fixed.read_bytes() == before
    assert convert_main(["--repair", str(cut), "-o", str(fixed), "--force"]) == 0
    again = tmp_path / "again"
    assert main([str(fixed), *args, "--out", str(again), "-q"]) == 0
    assert _rows(again)["madgwick"]["rmse_deg"] == pytest.approx(row["rmse_deg"], abs=1e-9)
    # a complete bag is not 'repaired'
    assert convert_main(["--repair", str(whole), "-o", str(tmp_path / "x.mcap")]) == 1
    assert "not truncated" in capsys.readouterr().err and not (tmp_path / "x.mcap").exists()


def test_truncated_mcap_with_nothing_readable(long_rec, tmp_path, capsys):
    whole = bagio.write_recording(tmp_path / "long.mcap", long_rec)
    cut = _cut(whole, tmp_path / "cut.mcap", 0.1)  # inside the first chunk
    assert main([str(cut), "-e", "madgwick", "--salvage", "--no-plots", "-q"]) == 1
    err = capsys.readouterr().err
    assert "truncated" in err and "no message before the cut is readable" in err


def test_truncated_sqlite3(long_rec, tmp_path, capsys):
    whole = bagio.write_recording(tmp_path / "long", long_rec, storage="sqlite3")
    cut_dir = tmp_path / "cut"
    cut_dir.mkdir()
    (cut_dir / "metadata.yaml").write_text((whole / "metadata.yaml").read_text())
    _cut(whole / "long.db3", cut_dir / "long.db3", 0.6)
    args = ["-e", "madgwick", "-s", "as-recorded", "--no-plots", "--offset-steps", "0", "-q"]
    assert main([str(cut_dir), *args]) == 1
    err = capsys.readouterr().err
    assert "truncated" in err and "where its header says" in err and "--salvage" in err
    n = _imu_count(err)
    assert 1000 < n < 4200 * 0.6
    out = tmp_path / "salvaged"
    assert main([str(cut_dir), *args, "--salvage", "--out", str(out)]) == 0
    assert _rows(out)["madgwick"]["n_samples"] == n
    fixed = tmp_path / "fixed"
    assert convert_main(["--repair", str(cut_dir), "-o", str(fixed)]) == 0
    assert bagio.bag_storage(fixed) == "sqlite3"
    rec = bagio.read_recording(fixed)
    assert len(rec) == n
    np.testing.assert_array_equal(rec.stamps_ns, long_rec.stamps_ns[:n])
