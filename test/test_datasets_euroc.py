"""The EuRoC/ASL reader (riann_ros.datasets.euroc) on folders the tests write: IMU data, ground-truth files in the
ASL, TUM and OpenVINS layouts, gap interpolation, bad-input messages."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from riann_ros import bagio
from riann_ros import quaternion as quat
from riann_ros.datasets import detect_format, read_any
from riann_ros.datasets.csvfile import InputError
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

