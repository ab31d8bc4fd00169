"""The saved calibration (:mod:`riann_ros.magcal.store`): round trip, atomic write that replaces only a calibration
file, refusal of bad files with a clear message, and a second run that starts converged from the first run's file."""

from __future__ import annotations

import math
import os
from pathlib import Path

import numpy as np
import pytest
import yaml

from riann_ros import quaternion as quat
from riann_ros.datasets.synthetic import generate
from riann_ros.magcal import store
from riann_ros.magcal.online import OnlineMagCalibrator
from riann_ros.magcal.records import CALIBRATED, UT, MagCalibration, MagCalPrior
from riann_ros.magcal.store import CalibrationFileError, load_calibration, save_calibration, to_yaml
from riann_ros.magcal.synthetic import FIELD_ENU_T, distort
from riann_ros.rotations import rotate

H_TRUE = np.array([20.0, 0.0, -10.0])


def calibration(**kw) -> MagCalibration:
    cov = np.diag(np.r_[np.full(9, 1e-4), np.full(3, (0.5e-6) ** 2)])
    base = dict(hard_iron_t=(2e-5, 0.0, -1e-5), soft_iron=(1.02, 0.01, 0.0, 0.01, 0.98, 0.0, 0.0, 0.0, 1.0),
                covariance=tuple(cov.reshape(144)), state=CALIBRATED, windows=12, converged_after_s=41.5,
                soft_iron_model="symmetric")
    base.update(kw)
    return MagCalibration(**base)  # type: ignore[arg-type]


def test_round_trip(tmp_path: Path):
    cal = calibration()
    path = save_calibration(tmp_path / "mag.yaml", cal)
    assert load_calibration(path) == cal
    doc = yaml.safe_load(path.read_text())
    assert doc["mag_hard_iron"] == list(cal.hard_iron_t) and doc["mag_soft_iron"] == list(cal.soft_iron)  # node names
    assert load_calibration(save_calibration(path, calibration(converged_after_s=None))).converged_after_s is None
    assert [p.name for p in tmp_path.iterdir()] == ["mag.yaml"]  # no temporary file left


def test_replaces_only_a_calibration_file(tmp_path: Path):
    other = tmp_path / "robot_params.yaml"
    other.write_text("riann_node:\n  ros__parameters:\n    use_mag: true\n")
    before = other.read_text()
    with pytest.raises(CalibrationFileError, match="not a magnetometer calibration file; not replaced"):
        save_calibration(other, calibration())
    assert other.read_text() == before
    save_calibration(other, calibration(), replace_other=True)  # when told to
    assert load_calibration(other) == calibration()
    with pytest.raises(CalibrationFileError, match="is a folder"):
        save_calibration(tmp_path, calibration())


def test_a_failed_write_leaves_the_old_file(tmp_path: Path, monkeypatch: pytest.MonkeyPatch):
    path = save_calibration(tmp_path / "mag.yaml", calibration())
    before = path.read_text()

    def fail(*_a, **_k):
        raise OSError(28, "No space left on device")

    monkeypatch.setattr(store.os, "replace", fail)
    with pytest.raises(OSError, match="No space"):
        save_calibration(path, calibration(windows=99))
    assert path.read_text() == before
    assert sorted(p.name for p in tmp_path.iterdir()) == ["mag.yaml"]


def _write(tmp_path: Path, doc: object, name: str = "bad.yaml") -> Path:
    p = tmp_path / name
    p.write_text(doc if isinstance(doc, str) else yaml.safe_dump(doc))
    return p


def _good_doc() -> dict:
    return yaml.safe_load(to_yaml(calibration()))


@pytest.mark.parametrize(("change", "message"), [
    (lambda d: d.pop("mag_calibration"), "no mag_calibration section"),
    (lambda d: d["mag_calibration"].update(format="riann_ros.magcal/99"), "format"),
    (lambda d: d.update(mag_hard_iron=[1.0, 2.0]), "mag_hard_iron must be a list of 3 numbers"),
    (lambda d: d.update(mag_hard_iron=[20.0, 0.0, -10.0]), "is over 933 µT"),
    (lambda d: d.update(mag_hard_iron=[999e-6, 0.0, 0.0]), "is over 933 µT"),  # the "999 µT" file
    (lambda d: d.update(mag_hard_iron=[float("nan"), 0.0, 0.0]), "finite"),
    (lambda d: d.update(mag_hard_iron=["a", 0.0, 0.0]), "list of 3 numbers"),
    (lambda d: d.update(mag_soft_iron=[1, 0, 0, 0, 1, 0, 0, 0, 0]), "singular"),
    (lambda d: d.update(mag_soft_iron=[-1, 0, 0, 0, 1, 0, 0, 0, 1]), "reflection"),
    (lambda d: d.update(mag_soft_iron=[-1, 0, 0, 0, -1, 0, 0, 0, 1]), "rotation of 180.0°"),
    (lambda d: d.update(mag_soft_iron=[1500, 0, 0, 0, 1500, 0, 0, 0, 1500]), "scales the field by 1500"),
    (lambda d: d["mag_calibration"].update(covariance=[1e308] * 144), "over its bound"),
    (lambda d: d["mag_calibration"].update(covariance=[0.0] * 143), "covariance must be a list of 144"),
    (lambda d: d["mag_calibration"].update(covariance=(-np.eye(12)).reshape(144).tolist()), "positive semi-definite"),
    (lambda d: d["mag_calibration"].update(state="great"), "state must be one of"),
    (lambda d: d["mag_calibration"].update(soft_iron_model="diag"), "soft_iron_model"),
    (lambda d: d["mag_calibration"].update(windows=-1), "windows"),
    (lambda d: d["mag_calibration"].update(converged_after_s="soon"), "converged_after_s"),
])
def test_bad_files_are_refused_with_a_clear_message(tmp_path: Path, change, message):
    doc = _good_doc()
    change(doc)
    path = _write(tmp_path, doc)
    with pytest.raises(CalibrationFileError, match=message) as e:
        load_calibration(path)
    assert str(path) in str(e.value)


def test_unreadable_or_not_yaml(tmp_path: Path):
    with pytest.raises(CalibrationFileError, match="cannot be read"):
        load_calibration(tmp_path / "missing.yaml")
    with pytest.raises(CalibrationFileError, match="not valid YAML"):
        load_calibration(_write(tmp_path, "a: [1, 2\n"))
    with pytest.raises(CalibrationFileError, match="no mag_calibration section"):
        load_calibration(_write(tmp_path, "- just a list\n"))
    (tmp_path / "bin.yaml").write_bytes(b"\xff\xfe\x00bad")
    with pytest.raises(CalibrationFileError, match="not valid YAML"):
        load_calibration(tmp_path / "bin.yaml")


def _feed(cal: OnlineMagCalibrator, rec, raw) -> np.ndarray:
    inc = quat.from_rotvec(rec.gyr * rec.dt[:, None]).tolist()
    err = np.empty(len(rec))
    north = math.atan2(FIELD_ENU_T[0], FIELD_ENU_T[1])
    for i in range(len(rec)):
        q = tuple(rec.quat_ref[i])
        u = cal.update(tuple(inc[i]), float(rec.dt[i]), tuple(raw[i]), 0.0, q)  # type: ignore[arg-type]
        assert u is not None
        mw = rotate(q, u)  # type: ignore[arg-type]
        err[i] = math.remainder(math.atan2(mw[0], mw[1]) - north, 2 * math.pi)
    return err


@pytest.mark.slow
def test_a_second_run_from_the_saved_file_starts_converged(tmp_path: Path):
    first = generate(duration=120, rate=100, motion="rotation", bias=0.0, gyr_noise=0.002, seed=11)
    raw1 = distort(first.quat_ref, H_TRUE * UT, noise_t=0.3e-6, seed=1)
    cal1 = OnlineMagCalibrator(soft_iron_model="symmetric")
    _feed(cal1, first, raw1)
    assert cal1.state == CALIBRATED
    path = save_calibration(tmp_path / "mag.yaml", cal1.calibration())
    # the next boot: another motion, the same sensor
    second = generate(duration=60, rate=100, motion="rotation", bias=0.0, gyr_noise=0.002, seed=12)
    raw2 = distort(second.quat_ref, H_TRUE * UT, noise_t=0.3e-6, seed=2)
    cal2 = OnlineMagCalibrator(MagCalPrior.from_calibration(load_calibration(path)), soft_iron_model="symmetric")
    err2 = _feed(cal2, second, raw2)
    # the file's hard iron carries the doubt of a new run (RUN_TO_RUN_HARD_IRON_SD_UT): its first windows confirm it
    assert cal2.converged_after_s is not None and cal2.converged_after_s < 10.0, cal2.converged_after_s
    # the proxy of the acceptance: over the whole run, the heading of the tilt-compensated field (true attitude)
    # is as good as with the true calibration (within 0.1°)
    err_true = np.array([math.remainder(v, 2 * math.pi) for v in np.arctan2(
        *quat.rotate(second.quat_ref, (raw2 / UT - H_TRUE) * UT)[:, :2].T) - math.atan2(*FIELD_ENU_T[:2])])
    rmse = lambda e: math.degrees(math.sqrt(float(np.mean(e * e))))  # noqa: E731
    assert abs(rmse(err2) - rmse(err_true)) < 0.1
    # and without the file, the same run starts uncalibrated and is worse at the start
    cal3 = OnlineMagCalibrator(soft_iron_model="symmetric")
    err3 = _feed(cal3, second, raw2)
    assert rmse(err3) > rmse(err2) + 1.0
    os.remove(path)


def test_a_saved_calibration_still_learns_a_changed_magnetic_situation():
    """A saved calibration is the hypothesis of the next run, its covariance widening the test's tolerance; should
    the robot's magnetics change (a payload, a magnet mounted 25 µT strong), the windows reject it and the estimate,
    which learns from the broad prior (not from the saved calibration's tight σ), finds the new hard iron."""
    first = generate(duration=120, rate=100, motion="rotation", bias=0.0, gyr_noise=0.002, seed=11)
    cal1 = OnlineMagCalibrator(soft_iron_model="symmetric")
    _feed(cal1, first, distort(first.quat_ref, H_TRUE * UT, noise_t=0.3e-6, seed=1))
    saved = MagCalPrior.from_calibration(cal1.calibration())
    second = generate(duration=90, rate=100, motion="rotation", bias=0.0, gyr_noise=0.002, seed=12)
    changed = H_TRUE + np.array([0.0, 25.0, 0.0])
    cal2 = OnlineMagCalibrator(saved, soft_iron_model="symmetric")
    err = _feed(cal2, second, distort(second.quat_ref, changed * UT, noise_t=0.3e-6, seed=2))
    assert not cal2.trusted
    assert np.abs(np.array(cal2.calibration().hard_iron_t) / UT - changed).max() < 1.0
    assert math.degrees(math.sqrt(float(np.mean(err[-2000:] ** 2)))) < 2.0  # the last 20 s: calibrated again


# ---- reads bounded in size and time; the file's mode; temporary files; never a downgrade ---------------------------
def _finishes_within(seconds: float, f, release=None):
    """``f()``'s result or exception, failing if it has not returned after ``seconds`` (``release()`` then unblocks
    it, so that the test does not hang)."""
    import threading

    out: dict = {}

    def run():
        try:
            out["value"] = f()
        except BaseException as e:
            out["error"] = e

    t = threading.Thread(target=run, daemon=True)
    t.start()
    t.join(seconds)
    if t.is_alive():
        if release is not None:
            release()
        t.join(5.0)
        pytest.fail(f"did not return within {seconds} s")
    return out


def _release_fifo(path: Path):
    def release():
        fd = os.open(path, os.O_WRONLY | os.O_NONBLOCK)
        os.close(fd)
    return release


def not_regular(tmp_path: Path) -> dict[str, tuple[Path, str]]:
    """Files that are not regular files, and what the refusal calls them."""
    fifo = tmp_path / "fifo.yaml"
    os.mkfifo(fifo)
    folder = tmp_path / "folder.yaml"
    folder.mkdir()
    return {"fifo": (fifo, "is a FIFO (named pipe)"), "dev_zero": (Path("/dev/zero"), "is a character device"),
            "folder": (folder, "is a folder")}


def test_only_regular_files_are_read_never_blocking(tmp_path: Path):
    for path, kind in not_regular(tmp_path).values():
        release = _release_fifo(path) if kind.startswith("is a FIFO") else None
        out = _finishes_within(1.0, lambda p=path: load_calibration(p), release)
        assert isinstance(out.get("error"), CalibrationFileError), out
        assert str(out["error"]) == f"{path}: {kind}, not a calibration file (not read)"
        assert _finishes_within(1.0, lambda p=path: store.is_calibration_file(p), release)["value"] is False
    # a FIFO or a folder at the target is never replaced
    fifo = tmp_path / "fifo.yaml"
    with pytest.raises(CalibrationFileError, match="is a FIFO"):
        save_calibration(fifo, calibration(), replace_other=True)
    assert sorted(p.name for p in tmp_path.iterdir()) == ["fifo.yaml", "folder.yaml"]


def test_reads_are_bounded_in_size(tmp_path: Path):
    huge = tmp_path / "huge.yaml"
    with huge.open("wb") as f:  # 4 GiB, sparse: nothing of it is read
        f.truncate(4 << 30)
    out = _finishes_within(1.0, lambda: load_calibration(huge))
    assert str(out["error"]) == f"{huge}: is {4 << 30} bytes, over the 64 KiB a calibration file can be (not read)"
    # a calibration with a comment that makes it just too large; the same just within the bound loads
    text = to_yaml(calibration())
    padded = tmp_path / "padded.yaml"
    padded.write_text(text + "#" * (store.MAX_FILE_BYTES - len(text.encode())) + "\n")
    with pytest.raises(CalibrationFileError, match="over the 64 KiB"):
        load_calibration(padded)
    padded.write_text(text + "#" * (store.MAX_FILE_BYTES - len(text.encode()) - 1) + "\n")
    assert load_calibration(padded) == calibration()
    # nesting as deep as 64 KiB allows (libyaml crashes composing it) is refused, flow and block style alike
    deep = _write(tmp_path, "[" * 30000 + "]" * 30000)
    with pytest.raises(CalibrationFileError, match="nested over 8 deep"):
        load_calibration(deep)
    with pytest.raises(CalibrationFileError, match="nested over 8 deep"):
        load_calibration(_write(tmp_path, "- " * 30000 + "x\n"))
    assert not store.is_calibration_file(deep)


def test_a_replaced_file_keeps_its_mode_a_new_one_gets_the_umask(tmp_path: Path):
    path = save_calibration(tmp_path / "mag.yaml", calibration())
    os.chmod(path, 0o640)
    save_calibration(path, calibration(windows=99))
    assert (path.stat().st_mode & 0o777) == 0o640 and load_calibration(path).windows == 99
    for umask, mode in ((0o077, 0o600), (0o022, 0o644)):
        old = os.umask(umask)
        try:
            new = save_calibration(tmp_path / f"new{umask:o}.yaml", calibration())
        finally:
            os.umask(old)
        assert (new.stat().st_mode & 0o777) == mode


def test_temporary_files_left_by_a_cut_off_save_are_removed(tmp_path: Path):
    path = save_calibration(tmp_path / "mag.yaml", calibration())
    left = tmp_path / ".mag.yaml.1a2b3c4d.tmp"
    left.write_text("half a calibra")
    other = tmp_path / ".other.yaml.1a2b3c4d.tmp"  # another file's: not ours to remove
    other.write_text("x")
    link = tmp_path / ".mag.yaml.link.tmp"  # a link is no file a save wrote
    link.symlink_to(path)
    assert store.remove_temporaries(path) == [left]
    assert sorted(p.name for p in tmp_path.iterdir()) == [".mag.yaml.link.tmp", ".other.yaml.1a2b3c4d.tmp", "mag.yaml"]
    assert store.remove_temporaries(tmp_path / "missing" / "mag.yaml") == []


def test_a_refused_calibration_is_never_written(tmp_path: Path):
    bad = calibration(soft_iron=(-1.0, 0.0, 0.0, 0.0, -1.0, 0.0, 0.0, 0.0, 1.0))
    with pytest.raises(CalibrationFileError, match="the calibration is refused: mag_soft_iron holds a rotation of 180"):
        save_calibration(tmp_path / "mag.yaml", bad)
    assert list(tmp_path.iterdir()) == []


def test_less_certain():
    file = calibration()  # calibrated, 0.5 µT per axis
    assert store.less_certain(calibration(state="converging"), file) == \
        "the file's calibration is calibrated, the current one converging"
    assert store.less_certain(calibration(state="uncalibrated"), calibration(state="converging")) is not None
    assert store.less_certain(calibration(state="calibrated"), calibration(state="converging")) is None
    wider = np.diag(np.r_[np.full(9, 1e-4), np.full(3, (0.8e-6) ** 2)])
    why = store.less_certain(calibration(covariance=tuple(wider.reshape(144))), file)
    assert why == "the file's hard iron is known to ±0.87 µT, the current one's to ±1.39 µT (both calibrated)"
    assert store.less_certain(file, calibration(covariance=tuple(wider.reshape(144)))) is None
    assert store.less_certain(calibration(windows=400), file) is None  # as certain: the newer one is written
