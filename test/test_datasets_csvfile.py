"""The generic CSV reader (riann_ros.datasets.csvfile) on files the tests write, its bad-input messages, and the
input format detection (riann_ros.datasets.detect_format)."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from riann_ros import bagio
from riann_ros.datasets import detect_format
from riann_ros.datasets.csvfile import InputError, read_csv, read_table
from riann_ros.datasets.euroc import read_ground_truth

GOOD = "t,acc_x,acc_y,acc_z,gyr_x,gyr_y,gyr_z,qw,qx,qy,qz,scored\n"


def _write(tmp_path: Path, text: str, name: str = "in.csv") -> Path:
    p = tmp_path / name
    p.write_text(text)
    return p


def test_csv_defaults_and_round_trip(tmp_path: Path) -> None:
    rows = [GOOD.strip()]
    for k in range(20):
        q = "1,0,0,0" if k != 5 else ",,,"
        rows.append(f"{1700000000 + k / 100:.2f},0.1,0.2,9.8,0.01,0.02,{k * 0.1!r},{q},{int(k >= 10)}")
    p = _write(tmp_path, "\n".join(rows) + "\n")
    assert detect_format(p) == "csv"
    rec = read_csv(p)
    assert rec.stamps_ns[0] == 1_700_000_000_000_000_000 and rec.stamps_ns[3] == 1_700_000_000_030_000_000
    assert np.isnan(rec.quat_ref[5]).all() and np.isfinite(np.delete(rec.quat_ref, 5, axis=0)).all()
    assert rec.score_mask.tolist() == [False] * 10 + [True] * 10
    back = bagio.read_recording(bagio.write_recording(tmp_path / "c.mcap", rec))
    assert np.array_equal(back.gyr, rec.gyr) and np.array_equal(back.quat_ref, rec.quat_ref, equal_nan=True)
    assert np.array_equal(back.score_mask, rec.score_mask)


def test_csv_units(tmp_path: Path) -> None:
    p = _write(tmp_path, "T\tax\tay\taz\tgx\tgy\tgz\n1000\t0\t0\t1\t90\t0\t0\n2000\t0\t0\t-1\t0\t180\t0\n")
    opts = {"time_col": "T", "acc_cols": ("ax", "ay", "az"), "gyr_cols": ("gx", "gy", "gz")}
    for unit, step in (("ns", 1000), ("us", 10**6), ("ms", 10**9)):
        rec = read_csv(p, time_unit=unit, acc_unit="g", gyr_unit="deg/s", **opts)
        assert rec.stamps_ns[1] - rec.stamps_ns[0] == step
    assert np.allclose(rec.acc[:, 2], [9.80665, -9.80665])
    assert np.allclose(rec.gyr[:, :2], [[np.pi / 2, 0], [0, np.pi]])
    assert rec.quat_ref is None and rec.score_mask.all()


@pytest.mark.parametrize(
    ("text", "opts", "pattern"),
    [
        (
            "t,acc_x,acc_y,acc_z,gyr_x,gyr_y\n0,0,0,1,0,0\n",
            {},
            r"in\.csv: no gyroscope column 'gyr_z' \(use --gyr-cols to name them; columns: t, acc_x, .*, gyr_y\)$",
        ),
        (
            "time,acc_x,acc_y,acc_z,gyr_x,gyr_y,gyr_z\n0,0,0,1,0,0,0\n",
            {},
            r"no time column 't' \(did you mean 'time'\? use --time-col to name it; columns: time, acc_x",
        ),
        (
            "t,Acc_X,acc_y,acc_z,gyr_x,gyr_y,gyr_z\n0,0,0,1,0,0,0\n",
            {},
            r"no accelerometer column 'acc_x' \(did you mean 'Acc_X'\? use --acc-cols",
        ),
        (
            "t,acc_x,acc_y,acc_z,gyr_x,gyr_y,gyr_z\n0,0,0,1,0,0,0\n",
            {"quat_cols": ("w", "x", "y", "z")},
            r"no quaternion columns 'w', 'x', 'y', 'z' \(use --quat-cols to name them",
        ),
        (
            "t,acc_x,acc_y,acc_z,gyr_x,gyr_y,gyr_z\n0,0,0,1,0,0,0\n1,0,0,1,0,0,0\n0.5,0,0,1,0,0,0\n",
            {},
            r"in\.csv:4: non-monotonic",
        ),
        (
            "t,acc_x,acc_y,acc_z,gyr_x,gyr_y,gyr_z,Scored\n0,0,0,1,0,0,0,1\n",
            {"mask_col": "scored"},
            r"no score mask column 'scored' \(did you mean 'Scored'\? use --mask-col to name it",
        ),
        (
            "#time(ns),ax,ay,az,gyro_x,gyro_y,gyro_z\n0,0,0,1,0,0,0\n",
            {"time_col": "time(ns)", "acc_cols": ("ax", "ay", "az")},
            r"no gyroscope columns 'gyr_x', 'gyr_y', 'gyr_z' \(did you mean 'gyro_x', 'gyro_y', 'gyro_z'\? use --gyr",
        ),
        (
            "#time(ns),acc_x,acc_y,acc_z,gyr_x,gyr_y,gyr_z\n0,0,0,1,0,0,0\n",
            {},
            r"no time column 't' \(did you mean 'time\(ns\)'\? use --time-col to name it",
        ),
        ("t,acc_x,acc_y,acc_z,gyr_x,gyr_y,gyr_z\n0,0,0,1,0,0,0\n0,0,0,1,0,0,0\n", {}, r"in\.csv:3: duplicated"),
        (
            "t,acc_x,acc_y,acc_z,gyr_x,gyr_y,gyr_z\n0,0,0,1,0,0,0\n1,nan,0,1,0,0,0\n",
            {},
            r"in\.csv:3: NaN/missing accelerometer value \(row 1, sample index 1\)",
        ),
        ("t,acc_x,acc_y,acc_z,gyr_x,gyr_y,gyr_z\n0,0,0,1,0,0,0\n1,0,0,1,,0,0\n", {}, r"in\.csv:3: NaN/missing gyro"),
        ("t,acc_x,acc_y,acc_z,gyr_x,gyr_y,gyr_z\n0,0,0,1,0,0,0\n1,0,0,1,abc,0,0\n", {}, r"in\.csv:3: .*'abc'"),
        (
            "t,acc_x,acc_y,acc_z,gyr_x,gyr_y,gyr_z\n0,0,0,1,0,0,0\n",
            {"time_unit": "fortnight"},
            r"unknown time unit 'fortnight'",
        ),
        (
            "t,acc_x,acc_y,acc_z,gyr_x,gyr_y,gyr_z\n0,0,0,1,0,0,0\n",
            {"acc_unit": "ft/s2"},
            r"unknown accelerometer unit",
        ),
        ("t,acc_x,acc_y,acc_z,gyr_x,gyr_y,gyr_z\n0,0,0,1,0,0,0\n", {"gyr_unit": "rpm"}, r"unknown gyroscope unit"),
        ("t,acc_x,acc_y,acc_z,gyr_x,gyr_y,gyr_z\n0,0,0,1,0,0\n", {}, r"in\.csv:2: 6 cells, the header has 7"),
        ("t,acc_x,acc_y,acc_z,gyr_x,gyr_y,gyr_z\n", {}, r"no data rows"),
        ("", {}, r"empty file"),
        ("t,acc_x,acc_y,acc_z,gyr_x,gyr_y,gyr_z,qw,qx,qy,qz\n0,0,0,1,0,0,0,2,0,0,0\n", {}, r"in\.csv:2: .*norm 2"),
        ("t,acc_x,acc_y,acc_z,gyr_x,gyr_y,gyr_z,scored\n0,0,0,1,0,0,0,maybe\n", {}, r"in\.csv:2: score mask"),
        ("t,acc_x,acc_y,acc_z,gyr_x,gyr_y,gyr_z\nx1,0,0,1,0,0,0\n", {}, r"in\.csv:2: bad time value 'x1'"),
        ("t,acc_x,acc_y,acc_z,gyr_x,gyr_y,gyr_z,t\n0,0,0,1,0,0,0,0\n", {}, r"duplicated column name\(s\) t"),
    ],
)
def test_csv_bad_inputs(tmp_path: Path, text: str, opts: dict, pattern: str) -> None:
    p = _write(tmp_path, text)
    with pytest.raises(InputError, match=pattern):
        read_csv(p, **opts)


def test_detect_format(tmp_path: Path) -> None:
    assert detect_format(_write(tmp_path, "", "x.hdf5")) == "broad"
    assert detect_format(_write(tmp_path, "", "x.mat")) == "broad"
    with pytest.raises(ValueError, match="--format"):
        detect_format(_write(tmp_path, "", "x.bin"))
    with pytest.raises(ValueError, match="--format"):
        detect_format(tmp_path)
    with pytest.raises(FileNotFoundError):
        detect_format(tmp_path / "nothing.csv")



def test_a_hash_line_is_a_header_only_where_the_rows_share_its_delimiter(tmp_path: Path) -> None:
    """ASL's ``#timestamp,…`` header is a header; a ``#`` comment holding ``,`` or ``;`` over blank-separated rows (a
    TUM file's, e.g. one another tool wrote) is a comment, so the TUM file reads."""
    asl = tmp_path / "asl.csv"
    asl.write_text("#timestamp [ns],q_RS_w,q_RS_x,q_RS_y,q_RS_z\n1000,1,0,0,0\n2000,1,0,0,0\n")
    assert read_table(asl)[0] == ["timestamp [ns]", "q_RS_w", "q_RS_x", "q_RS_y", "q_RS_z"]
    tum = tmp_path / "est.tum"
    tum.write_text("# t x y z qx qy qz qw (my filter; v2, position not estimated)\n# second comment, too\n"
                   "1.0 0 0 0 0 0 0 1\n1.5 0 0 0 0 0 0.7071067811865476 0.7071067811865476\n")
    stamps, q = read_ground_truth(tum)
    assert stamps.tolist() == [1_000_000_000, 1_500_000_000]
    assert np.allclose(q, [[1, 0, 0, 0], [0.7071067811865476, 0, 0, 0.7071067811865476]])
