"""riann-bag-convert end to end: every BROAD trial through the CLI and back, synthetic, CSV, errors."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from riann_ros import bagio
from riann_ros.cli.convert import main
from riann_ros.datasets.broad import broad_files, find_broad_dir, read_broad


def _broad_dir() -> Path:
    d = find_broad_dir()
    if d is None:
        pytest.skip("BROAD not found (set RIANN_BROAD_DIR or provide ../shared/datasets/broad)")
    return d


def _check_same(src, back) -> None:
    assert np.array_equal(back.stamps_ns, src.stamps_ns)
    assert np.array_equal(back.acc, src.acc)  # exact float64
    assert np.array_equal(back.gyr, src.gyr)
    assert np.array_equal(back.quat_ref, src.quat_ref, equal_nan=True)  # NaN rows absent → NaN
    assert np.array_equal(back.score_mask, src.score_mask)
    assert (back.name, back.dataset, back.source) == (src.name, src.dataset, src.source)


@pytest.mark.broad
@pytest.mark.slow
def test_broad_folder_round_trip(tmp_path: Path) -> None:
    d = _broad_dir()
    files = broad_files(d)
    assert files
    out = tmp_path / "bags"
    assert main([str(d), "-o", str(out), "-q"]) == 0
    for f in files:
        src = read_broad(f)
        bag = out / f"{f.stem}.mcap"
        assert bag.is_file()
        back = bagio.read_recording(bag)
        _check_same(src, back)
        n_ref = int(np.isfinite(src.quat_ref).all(axis=1).sum())
        assert n_ref < len(src)  # BROAD trials all have gaps; absent rows must come back as NaN
    assert sorted(p.name for p in out.iterdir()) == sorted(f"{f.stem}.mcap" for f in files)


@pytest.mark.broad
@pytest.mark.parametrize(("storage", "compression"), [("sqlite3", "none"), ("sqlite3", "zstd"), ("mcap", "zstd")])
def test_broad_one_trial_other_storages(tmp_path: Path, storage: str, compression: str) -> None:
    d = _broad_dir()
    files = broad_files(d)
    f = next((x for x in files if x.suffix == ".mat"), files[0])
    out = tmp_path / "one"
    rc = main([str(f), "-o", str(out), "--storage", storage, "--compression", compression, "--frame-id", "myon", "-q"])
    assert rc == 0
    back = bagio.read_recording(out)
    _check_same(read_broad(f), back)
    assert back.frame_id == "myon"


def test_synthetic_cli(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    out = tmp_path / "s.mcap"
    argv = ["--format", "synthetic", "--rate", "100", "--duration", "10", "--seed", "7", "--bias", "0.01,0,-0.02"]
    assert main([*argv, "-o", str(out), "--compression", "zstd"]) == 0
    rec = bagio.read_recording(out)
    assert len(rec) == 1001 and rec.dataset == "synthetic" and rec.meta["seed"] == "7"
    assert rec.meta["gyr_bias_rad_s"] == "0.01 0.0 -0.02"
    assert np.isfinite(rec.quat_ref).all()
    # refuse an existing output, non-zero exit, clear message
    capsys.readouterr()
    assert main([*argv, "-o", str(out)]) == 1
    err = capsys.readouterr().err
    assert "exists" in err and "--force" in err and str(out) in err
    assert main([*argv, "--seed", "8", "-o", str(out), "--force", "-q"]) == 0
    assert bagio.read_recording(out).meta["seed"] == "8"


def test_cli_csv_with_units(tmp_path: Path) -> None:
    csv = tmp_path / "imu.csv"
    rows = ["time_ms;ax;ay;az;gx;gy;gz;x;y;z;w;use"]
    for k in range(50):
        rows.append(f"{1000 + 10 * k};0;0;1;{k};0;0;0;0;0;1;{int(k > 20)}")
    csv.write_text("\n".join(rows) + "\n")
    out = tmp_path / "c.mcap"
    argv = [
        str(csv), "-o", str(out), "--time-col", "time_ms", "--time-unit", "ms", "--acc-cols", "ax,ay,az",
        "--acc-unit", "g", "--gyr-cols", "gx,gy,gz", "--gyr-unit", "deg/s", "--quat-cols", "x,y,z,w",
        "--quat-order", "xyzw", "--mask-col", "use", "-q",
    ]  # fmt: skip
    assert main(argv) == 0
    rec = bagio.read_recording(out)
    assert rec.stamps_ns[0] == 1_000_000_000 and rec.stamps_ns[1] - rec.stamps_ns[0] == 10_000_000
    assert np.allclose(rec.acc[:, 2], 9.80665)
    assert np.allclose(rec.gyr[:, 0], np.deg2rad(np.arange(50)))
    assert np.array_equal(rec.quat_ref, np.tile([1.0, 0, 0, 0], (50, 1)))
    assert rec.score_mask.sum() == 29


def test_cli_errors(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    csv = tmp_path / "bad.csv"
    csv.write_text("t,acc_x,acc_y,acc_z,gyr_x,gyr_y,gyr_z\n0,0,0,9.8,0,0,0\n0.01,0,0,9.8,0,0,0\n0.01,0,0,9.8,0,0,0\n")
    out = tmp_path / "o.mcap"
    assert main([str(csv), "-o", str(out)]) == 1
    err = capsys.readouterr().err
    assert "bad.csv:4" in err and "duplicated" in err
    assert not out.exists()
    assert main([str(csv), "-o", str(out), "--acc-unit", "furlong"]) == 1
    assert "unknown accelerometer unit 'furlong'" in capsys.readouterr().err
    assert main([str(tmp_path / "nope.csv"), "-o", str(out)]) == 1
    assert "no such file" in capsys.readouterr().err
    weird = tmp_path / "data.xyz"
    weird.write_text("x")
    assert main([str(weird), "-o", str(out)]) == 1
    assert "--format" in capsys.readouterr().err
    with pytest.raises(SystemExit) as e:
        main(["--format", "synthetic", "-o", str(out), "--storage", "rosbag1"])
    assert e.value.code == 2
    assert main(["--format", "synthetic", "-o", str(out), "--storage", "sqlite3"]) == 1
    assert "--storage mcap" in capsys.readouterr().err
    assert list(tmp_path.iterdir()) == [csv, weird] or sorted(tmp_path.iterdir()) == sorted([csv, weird])


def test_cli_folder_continues_after_failure(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    src = tmp_path / "in"
    src.mkdir()
    good = "t,acc_x,acc_y,acc_z,gyr_x,gyr_y,gyr_z\n0,0,0,9.8,0,0,0\n0.01,0,0,9.8,0,0,0\n"
    (src / "a.csv").write_text(good)
    (src / "b.csv").write_text("t,acc_x,acc_y,acc_z,gyr_x,gyr_y\n0,0,0,9.8,0,0\n")
    out = tmp_path / "out"
    assert main([str(src), "-o", str(out), "--format", "csv", "-q"]) == 1
    err = capsys.readouterr().err
    assert "b.csv" in err and "gyr_z" in err and "1 of 2" in err
    assert [p.name for p in out.iterdir()] == ["a.mcap"]


def test_cli_failure_half_way_leaves_no_bag(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str]
) -> None:
    from rosbags.rosbag2 import Writer

    real = Writer.write
    count = {"n": 0}

    def failing(self, conn, t, data):
        count["n"] += 1
        if count["n"] > 1000:
            raise OSError(28, "No space left on device")
        return real(self, conn, t, data)

    monkeypatch.setattr(Writer, "write", failing)
    out = tmp_path / "half.mcap"
    assert main(["--format", "synthetic", "--duration", "20", "-o", str(out)]) == 1
    assert "No space left on device" in capsys.readouterr().err
    assert list(tmp_path.iterdir()) == []


def test_example_bags_are_reproducible_and_small(tmp_path: Path) -> None:
    """bags/*.mcap: each < 2 MB and regenerated bit-for-bit (samples) by the commands in make_bags.sh."""
    import shlex

    root = Path(__file__).resolve().parents[1]
    script = (root / "bags" / "make_bags.sh").read_text().splitlines()
    commands = [shlex.split(line)[1:] for line in script if line.startswith("$CONVERT")]
    assert len(commands) >= 2
    for argv in commands:
        i = argv.index("-o")
        committed = root / argv[i + 1]
        assert committed.is_file() and committed.stat().st_size < 2_000_000
        out = tmp_path / committed.name
        assert main([*argv[:i], *argv[i + 2 :], "-o", str(out), "-q"]) == 0
        a, b = bagio.read_recording(committed), bagio.read_recording(out)
        _check_same(a, b)
        assert a.meta == b.meta
    assert sorted(p.name for p in (root / "bags").glob("*.mcap")) == sorted(
        Path(c[c.index("-o") + 1]).name for c in commands
    )


def test_empty_imu_topic_is_an_error(tmp_path: Path) -> None:
    from rosbags.rosbag2 import Writer

    p = tmp_path / "empty"
    with Writer(p, version=9) as w:
        w.add_connection(bagio.IMU_TOPIC, bagio.IMU_TYPE, typestore=bagio.typestore())
    with pytest.raises(bagio.BagError, match="no messages"):
        bagio.read_recording(p)
