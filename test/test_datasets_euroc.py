"""EuRoC/ASL folders and generic CSV files written by the tests themselves; bad-input messages."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from riann_ros import bagio
from riann_ros import quaternion as quat
from riann_ros.datasets import detect_format, read_any
from riann_ros.datasets.csvfile import InputError, read_csv
from riann_ros.datasets.euroc import interpolate, read_euroc

IMU_HEADER = (
    "#timestamp [ns],w_RS_S_x [rad s^-1],w_RS_S_y [rad s^-1],w_RS_S_z [rad s^-1],"
    "a_RS_S_x [m s^-2],a_RS_S_y [m s^-2],a_RS_S_z [m s^-2]"
)
GT_HEADER = (
    "#timestamp, p_RS_R_x [m], p_RS_R_y [m], p_RS_R_z [m], q_RS_w [], q_RS_x [], q_RS_y [], q_RS_z [], "
    "v_RS_R_x [m s^-1], v_RS_R_y [m s^-1], v_RS_R_z [m s^-1]"
)
T0 = 1403636579758555392  # an EuRoC-like epoch stamp (does not fit a float64 exactly)


def _yaw(a: np.ndarray) -> np.ndarray:
    return np.stack([np.cos(a / 2), 0 * a, 0 * a, np.sin(a / 2)], axis=1)


def _euroc(tmp_path: Path, n: int = 200, gt: bool = True) -> tuple[Path, np.ndarray, np.ndarray]:
    root = tmp_path / "MH_test"
    imu = root / "mav0" / "imu0"
    imu.mkdir(parents=True)
    stamps = T0 + np.arange(n, dtype=np.int64) * 5_000_000  # 200 Hz
    rng = np.random.default_rng(0)
    data = rng.normal(size=(n, 6))  # gyr rad/s, acc m/s² around gravity: passes the converter's unit checks
    data[:, 5] += 9.81
    lines = [IMU_HEADER] + [f"{s},{','.join(repr(float(v)) for v in row)}" for s, row in zip(stamps, data, strict=True)]
    (imu / "data.csv").write_text("\n".join(lines) + "\n")
    if gt:
        g = root / "mav0" / "state_groundtruth_estimate0"
        g.mkdir(parents=True)
        gt_st = T0 + 50_000_000 + np.arange(0, 150) * 5_000_000 + 1_000_000  # starts 50 ms late, offset 1 ms
        q = _yaw(np.linspace(0, 1.0, len(gt_st)))
        rows = [GT_HEADER] + [
            f"{s},0,0,0," + ",".join(repr(float(v)) for v in q[i]) + ",0,0,0" for i, s in enumerate(gt_st)
        ]
        (g / "data.csv").write_text("\n".join(rows) + "\n")
    return root, stamps, data


def test_euroc_folder(tmp_path: Path) -> None:
    root, stamps, data = _euroc(tmp_path)
    assert detect_format(root) == "euroc"
    rec = read_any(root)
    assert np.array_equal(rec.stamps_ns, stamps)
    assert np.array_equal(rec.gyr, data[:, :3]) and np.array_equal(rec.acc, data[:, 3:])
    gt_t0, gt_t1 = T0 + 51_000_000, T0 + 51_000_000 + 149 * 5_000_000
    inside = (stamps >= gt_t0) & (stamps <= gt_t1)
    assert np.isnan(rec.quat_ref[~inside]).all() and np.isfinite(rec.quat_ref[inside]).all()
    # yaw is linear in time, so slerp gives exactly the yaw at the IMU stamps
    yaw = (stamps[inside] - gt_t0) / (gt_t1 - gt_t0) * 1.0
    assert np.allclose(rec.quat_ref[inside], _yaw(yaw), atol=1e-12)
    # round trip through a bag
    back = bagio.read_recording(bagio.write_recording(tmp_path / "e.mcap", rec))
    assert np.array_equal(back.quat_ref, rec.quat_ref, equal_nan=True) and np.array_equal(back.stamps_ns, stamps)


def test_euroc_cli_imu_to_body(tmp_path: Path) -> None:
    from riann_ros.cli.convert import main

    root, _, _ = _euroc(tmp_path)
    q_bi = [float(np.cos(0.25)), float(np.sin(0.25)), 0.0, 0.0]  # IMU rotated 0.5 rad about body x
    out = tmp_path / "e.mcap"
    assert main([str(root), "-o", str(out), "--imu-to-body", ",".join(map(str, q_bi)), "-q"]) == 0
    rec = bagio.read_recording(out)
    plain = read_euroc(root)
    ok = np.isfinite(plain.quat_ref).all(axis=1)
    assert np.allclose(rec.quat_ref[ok], quat.multiply(plain.quat_ref[ok], q_bi))
    with pytest.raises(SystemExit) as e:  # not a unit quaternion: usage error
        main([str(root), "-o", str(tmp_path / "f.mcap"), "--imu-to-body", "1,1,0,0"])
    assert e.value.code == 2


def test_euroc_tum_ground_truth_and_no_gt(tmp_path: Path) -> None:
    root, _, _ = _euroc(tmp_path, gt=False)
    assert read_euroc(root).quat_ref is None
    tum = tmp_path / "gt.txt"
    t_ns = T0 + np.arange(0, 200, 10) * 5_000_000
    t = [f"{int(x) // 10**9}.{int(x) % 10**9:09d}" for x in t_ns]  # exact decimal seconds
    q = _yaw(np.linspace(0, 0.5, len(t)))
    lines = ["# timestamp tx ty tz qx qy qz qw"] + [
        f"{ti} 1 2 3 " + " ".join(repr(float(v)) for v in qi[[1, 2, 3, 0]]) for ti, qi in zip(t, q, strict=True)
    ]
    tum.write_text("\n".join(lines) + "\n")
    rec = read_euroc(root, ground_truth=tum)
    ok = np.isfinite(rec.quat_ref).all(axis=1)
    assert ok.sum() >= 180 and np.isnan(rec.quat_ref[-5:]).all()
    assert np.allclose(rec.quat_ref[::10][:19], q[:19], atol=1e-12)  # exact at the ground-truth stamps
    assert quat.total_error(rec.quat_ref[ok][-1:], q[-1:])[0] < 1e-9


def test_euroc_bad_inputs(tmp_path: Path) -> None:
    with pytest.raises(InputError, match="not an EuRoC"):
        read_euroc(tmp_path)
    root, _, _ = _euroc(tmp_path, n=20, gt=False)
    f = root / "mav0" / "imu0" / "data.csv"
    text = f.read_text().splitlines()
    f.write_text("\n".join([text[0].replace("w_RS_S_y", "w_RS_S_Y"), *text[1:]]) + "\n")
    with pytest.raises(InputError, match=r"data\.csv: no EuRoC IMU column 'w_RS_S_y' \(did you mean 'w_RS_S_Y \[rad"):
        read_euroc(root)
    text[5], text[6] = text[6], text[5]
    f.write_text("\n".join(text) + "\n")
    with pytest.raises(InputError, match=r"data\.csv:7: non-monotonic"):
        read_euroc(root)


def _gt_cell(name: str, t: str, quat: dict[str, str]) -> str:
    """The cell of column ``name``: a quaternion component (q*/rot* ending in w/x/y/z), the time (t*/stamp*), or 0."""
    n = name.strip().lstrip("#").split("[")[0].split("(")[0].strip().lower()
    if n.startswith(("q", "rot")):
        return quat[n[-1]]
    return t if n.startswith(("t", "stamp")) else "0"


def _gt_file(path: Path, header: str, stamps_ns: np.ndarray, q: np.ndarray, scale: int = 1, sep: str = ",") -> Path:
    """A ground-truth CSV with columns ``header``: time ``stamps_ns / scale`` (exact decimal), ``q`` (w, x, y, z)."""
    rows = [header]
    for s, qi in zip(stamps_ns, q, strict=True):
        t = str(int(s) // scale) if scale <= 1000 else f"{int(s) // scale}.{int(s) % scale:0{len(str(scale)) - 1}d}"
        quat = dict(zip("wxyz", (repr(float(v)) for v in qi), strict=True))
        rows.append(sep.join(_gt_cell(name, t, quat) for name in header.split(sep)))
    path.write_text("\n".join(rows) + "\n")
    return path


def _gt_case(tmp_path: Path):
    root, _, _ = _euroc(tmp_path, gt=False)
    gt_st = T0 + 50_000_000 + np.arange(0, 150) * 5_000_000 + 1_000_000
    return root, gt_st, _yaw(np.linspace(0, 1.0, len(gt_st)))


def test_euroc_open_vins_ground_truth(tmp_path: Path) -> None:
    """#time(ns),px,py,pz,qw,qx,qy,qz[,...] (open_vins / vicon2gt): columns by name, any order, ns."""
    root, gt_st, q = _gt_case(tmp_path)
    asl = _gt_file(tmp_path / "asl.csv", GT_HEADER.replace(", ", ","), gt_st, q)
    expected = read_euroc(root, ground_truth=asl).quat_ref
    assert np.isfinite(expected).all(axis=1).sum() == 149  # the IMU samples inside the ground truth's span
    ov = _gt_file(tmp_path / "room1_gt.csv", "#time(ns),px,py,pz,qw,qx,qy,qz,vx,vy,vz", gt_st, q)
    assert np.array_equal(read_euroc(root, ground_truth=ov).quat_ref, expected, equal_nan=True)
    _gt_file(ov, "qx,pz,#time(ns),qz,px,qw,qy", gt_st, q)  # any order, fewer columns
    assert np.array_equal(read_euroc(root, ground_truth=ov).quat_ref, expected, equal_nan=True)
    _gt_file(ov, "Timestamp [s];qw;qx;qy;qz", gt_st, q, scale=10**9, sep=";")  # the unit in the name is used
    assert np.allclose(read_euroc(root, ground_truth=ov).quat_ref, expected, equal_nan=True, atol=1e-12)


def test_euroc_gt_cols_and_time_unit(tmp_path: Path) -> None:
    """--gt-cols TIME,QW,QX,QY,QZ maps other names; --gt-time-unit sets the unit; through the CLI."""
    from riann_ros.cli.convert import main

    root, gt_st, q = _gt_case(tmp_path)
    expected = read_euroc(root, ground_truth=_gt_file(tmp_path / "ov.csv", "#time(ns),qw,qx,qy,qz", gt_st, q)).quat_ref
    header = "stamp,x,y,z,rot_w,rot_x,rot_y,rot_z"
    gt = _gt_file(tmp_path / "mocap.csv", header, gt_st, q, scale=10**9)  # seconds, no unit in the name
    out = tmp_path / "m.mcap"
    argv = [str(root), "--ground-truth", str(gt), "--gt-cols", "stamp,rot_w,rot_x,rot_y,rot_z", "-o", str(out), "-q"]
    assert main([*argv, "--gt-time-unit", "s"]) == 0
    assert np.allclose(bagio.read_recording(out).quat_ref, expected, equal_nan=True, atol=1e-12)
    # without --gt-time-unit the seconds are read as ns: 5 ms steps round to the same ns, and the message says why
    cols = ("stamp", "rot_w", "rot_x", "rot_y", "rot_z")
    with pytest.raises(InputError, match=r"mocap\.csv:3: duplicated time stamp .*read in ns.*--gt-time-unit\)$"):
        read_euroc(root, ground_truth=gt, gt_cols=cols)
    # microseconds read as ns: no overlap with the IMU, a clear error instead of a bag without reference
    _gt_file(gt, header, gt_st, q, scale=1000)
    with pytest.raises(
        InputError,
        match=r"mocap\.csv: the ground truth \(1403636\.580 s – 1403636\.581 s\) does not overlap the IMU data "
        r"\(1403636579\.759 s – .*is its time unit right \(--gt-time-unit\)\?$",
    ):
        read_euroc(root, ground_truth=gt, gt_cols=cols)
    us = read_euroc(root, ground_truth=gt, gt_cols=cols, gt_time_unit="us").quat_ref
    both = np.isfinite(us).all(axis=1) & np.isfinite(expected).all(axis=1)
    assert both.sum() >= 148 and np.allclose(us[both], expected[both], atol=1e-6)  # stamps truncated to 1 us
    with pytest.raises(SystemExit) as e:  # 5 names needed: usage error
        main([str(root), "-o", str(out), "--gt-cols", "stamp,rot_w"])
    assert e.value.code == 2


@pytest.mark.parametrize(
    ("header", "opts", "pattern"),
    [
        (
            "#time(ns),px,py,pz,q_w,q_x,q_y,q_z",
            {},
            r"gt\.csv: no ground-truth columns 'qw', 'qx', 'qy', 'qz' \(did you mean 'q_w', 'q_x', 'q_y', 'q_z'\? "
            r"use --gt-cols to name them; columns: time\(ns\), px.*known layouts: ASL",
        ),
        ("sec,px,py,pz,qw,qx,qy,qz", {}, r"no ground-truth column 'time' \(did you mean 'sec'\? use --gt-cols"),
        (
            "stamp,x,y,z,rot_w,rot_x,rot_y,rot_z",
            {"gt_cols": ("stamp", "rot_w", "rotx", "rot_y", "rot_z")},
            r"gt\.csv: no ground-truth column 'rotx' \(did you mean 'rot_x'\? use --gt-cols",
        ),
        (
            "stamp,x,y,z,rot_w,rot_x,rot_y,rot_z",
            {"gt_cols": ("time", "rot_w", "rot_x", "rot_y", "rot_z")},
            r"no ground-truth column 'time' \(did you mean 'stamp'\?",
        ),
    ],
)
def test_euroc_ground_truth_column_errors(tmp_path: Path, header: str, opts: dict, pattern: str) -> None:
    root, gt_st, q = _gt_case(tmp_path)
    gt = _gt_file(tmp_path / "gt.csv", header, gt_st, q)
    with pytest.raises(InputError, match=pattern):
        read_euroc(root, ground_truth=gt, **opts)


def test_euroc_ground_truth_all_in_gaps(tmp_path: Path) -> None:
    root, _, _ = _gt_case(tmp_path)
    gt_st = T0 - 10**9 + np.array([0, 5 * 10**9])  # spans the IMU data, but one 5 s gap
    gt = _gt_file(tmp_path / "gt.csv", "#time(ns),qw,qx,qy,qz", gt_st, _yaw(np.zeros(2)))
    with pytest.raises(
        InputError, match=r"gt\.csv: every IMU sample falls in a ground-truth gap longer than --max-gap"
    ):
        read_euroc(root, ground_truth=gt)
    assert np.isfinite(read_euroc(root, ground_truth=gt, max_gap_s=10).quat_ref).all()


def test_interpolate_gaps() -> None:
    gt = np.array([0, 10, 20, 500, 510], dtype=np.int64) * 1_000_000
    q = _yaw(np.array([0.0, 0.1, 0.2, 0.3, 0.4]))
    st = np.array([-5, 0, 5, 20, 100, 505, 510, 600], dtype=np.int64) * 1_000_000
    out = interpolate(gt, q, st, max_gap_s=0.1)
    ok = np.isfinite(out).all(axis=1)
    assert ok.tolist() == [False, True, True, True, False, True, True, False]
    assert np.allclose(out[2], _yaw(np.array([0.05]))[0])


# ---- generic CSV -----------------------------------------------------------------------------------

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


# ---- unit checks (riann_ros.datasets.units) ---------------------------------------------------------


def _imu(rate: float = 200.0, n: int = 1000, acc_scale: float = 1.0, gyr_scale: float = 1.0, seed: int = 0):
    """Half rest (gravity on z, gyro noise), half rotation at up to ~6 rad/s; units scaled by the arguments."""
    from riann_ros.recording import Recording

    rng = np.random.default_rng(seed)
    gyr = rng.normal(0, 0.01, (n, 3))
    gyr[n // 2 :] += 6.0 * np.sin(np.linspace(0, 20, n - n // 2))[:, None] * [1, 0.5, 0.2]
    acc = rng.normal(0, 0.05, (n, 3)) + np.array([0, 0, 9.81])
    stamps = np.round(np.arange(n) * 1e9 / rate).astype(np.int64)
    return Recording(stamps_ns=stamps, acc=acc * acc_scale, gyr=gyr * gyr_scale)


def test_units_plausible_inputs_pass() -> None:
    from riann_ros.datasets.synthetic import generate
    from riann_ros.datasets.units import check_units

    assert check_units(_imu()) == []
    for rate in (1.0, 10.0, 1000.0, 10_000.0):  # the range ends are plausible
        assert check_units(_imu(rate=rate)) == [], rate
    for motion in ("combined", "rotation", "translation"):
        for rate in (50.0, 1000.0):
            assert check_units(generate(rate=rate, duration=30, seed=5, motion=motion)) == [], (motion, rate)
    # fast, large motion: the median |acc| over all samples is ~19 m/s², at rest it is gravity
    assert check_units(generate(rate=200, duration=30, seed=1, speed=3, max_tilt_deg=90)) == []


@pytest.mark.broad
def test_units_broad_trials_pass() -> None:
    from riann_ros.datasets.broad import broad_files, find_broad_dir, read_broad
    from riann_ros.datasets.units import check_units

    d = find_broad_dir()
    if d is None:
        pytest.skip("BROAD not found")
    for f in broad_files(d):
        assert check_units(read_broad(f)) == [], f.name


@pytest.mark.parametrize(
    ("rate", "time_unit", "suggest"),
    [(0.2, "s", "ms"), (0.0002, "s", "us"), (0.0000002, "s", "ns"), (200_000.0, "ms", "s"), (2e5, "ns", "us")],
)
def test_units_rate_suggests_the_unit_that_fits(rate: float, time_unit: str, suggest: str) -> None:
    from riann_ros.datasets.units import check_units

    (f,) = check_units(_imu(rate=rate), time_unit=time_unit)
    assert (f.check, f.flag, f.suggest, f.unit) == ("rate", "--time-unit", suggest, time_unit)
    assert f.value == pytest.approx(rate) and f"looks like {suggest} stamps read as {time_unit}" in str(f)


def test_units_rate_both_candidates_and_none() -> None:
    from riann_ros.datasets.units import check_units

    # a 2 Hz log in ms read as s: 0.002 Hz; ms → 2 Hz and us → 2 kHz are both in range: the nearer to 200 Hz wins
    (f,) = check_units(_imu(rate=0.002, n=50))
    assert f.suggest == "us"
    (f,) = check_units(_imu(rate=0.2, n=50), time_unit="ns")  # already the finest unit: nothing fits
    assert f.suggest is None and "no time unit" in str(f)
    assert check_units(_imu(n=1)) == []  # one sample: no rate to check


def test_units_gravity_and_gyro() -> None:
    from riann_ros.constants import GRAVITY
    from riann_ros.datasets.units import check_units

    (f,) = check_units(_imu(acc_scale=1 / GRAVITY))  # g read as m/s²
    assert (f.check, f.flag, f.suggest) == ("acc", "--acc-unit", "g") and f.value == pytest.approx(1.0, abs=0.01)
    assert "samples at rest" in str(f)
    (f,) = check_units(_imu(acc_scale=GRAVITY), acc_unit="g")  # m/s² data read as g (×9.81 when read)
    assert f.suggest == "m/s2"
    (f,) = check_units(_imu(acc_scale=1000 / GRAVITY))  # mg: no supported unit
    assert f.suggest is None and "implausible" in str(f)
    (f,) = check_units(_imu(gyr_scale=180 / np.pi))  # deg/s read as rad/s; rest found with the corrected gyro
    assert (f.check, f.flag, f.suggest) == ("gyr", "--gyr-unit", "deg/s") and f.value > 35
    (f,) = check_units(_imu(gyr_scale=1000 * 180 / np.pi))  # mdps: too large in every unit
    assert f.suggest is None


def test_units_rest_fallback_and_unit_tables() -> None:
    from riann_ros.datasets import units
    from riann_ros.datasets.csvfile import ACC_UNITS, GYR_UNITS, TIME_UNITS

    rec = _imu()
    rec.gyr[:] = 1.0  # never at rest: the median is over all samples
    rec.acc[:] = [0, 0, 1.0]
    (f,) = units.check_units(rec)
    assert "all 1000 samples (none at rest)" in str(f) and f.suggest == "g"
    rec.acc[:] = [0, 0, 9.81 * units.GRAVITY]
    rec.meta.update(acc_unit="g")  # the CSV reader records the units it read: used by default
    assert units.check_units(rec)[0].suggest == "m/s2"
    # every unit the CSV reader accepts is known to the checks, with the same scale
    tables = ((TIME_UNITS, units.TIME_SCALES), (ACC_UNITS, units.ACC_SCALES), (GYR_UNITS, units.GYR_SCALES))
    for table, scales in tables:
        for name, scale in table.items():
            assert scales[units.canonical_unit(name, scales)] == pytest.approx(scale), name


@pytest.mark.parametrize(("scale", "unit", "suggest"), [(1.0, "T", None), (1e4, "T", "G"), (1e6, "T", "uT"),
                                                        (1e9, "T", "nT"), (1e-2, "uT", "G")])
def test_units_magnetic_field(scale: float, unit: str, suggest: str | None) -> None:
    """Earth's field (45 µT) is plausible in tesla; the same numbers in another unit are named."""
    from riann_ros.datasets.units import check_units

    rec = _imu()
    rng = np.random.default_rng(0)
    d = rng.normal(size=(len(rec), 3))
    rec.mag = 45e-6 * d / np.linalg.norm(d, axis=1, keepdims=True) * scale
    rec.meta["mag_unit"] = unit
    found = [f for f in check_units(rec) if f.check == "mag"]
    if scale == 1.0:
        assert found == []
    else:
        assert len(found) == 1 and found[0].option == "mag_unit"
        assert found[0].suggest == suggest, found[0]


@pytest.mark.broad
def test_broad_magnetometer_in_tesla() -> None:
    from riann_ros.datasets.broad import broad_files, find_broad_dir, read_broad

    d = find_broad_dir()
    if d is None:
        pytest.skip("BROAD not found")
    rec = read_broad(broad_files(d)[0])
    assert rec.mag is not None and rec.mag.shape == (len(rec), 3)
    assert 25e-6 < np.median(np.linalg.norm(rec.mag, axis=1)) < 65e-6
