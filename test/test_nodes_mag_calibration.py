"""The saved magnetometer calibration over real DDS (riann_ros.nodes.mag_calibration): ``~/save_mag_calibration``
writes the online calibration atomically to ``mag_calibration_file`` and the next start loads it (the node equal to
the offline estimator within 1e-4 with the calibration on, before and after); a bad file is refused with one clear
message and the node runs on its parameters, and the service never replaces it; /diagnostics shows the state.
``~/reset`` keeps the calibration the node learned (the robot's); ``~/restart`` builds the estimator as at start: its
calibration starts again from the file read at start (which it leaves as it is), or from ``mag_hard_iron`` set since."""

from __future__ import annotations

import os
import stat
import threading
import time

import numpy as np
import pytest
import yaml
from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus
from geometry_msgs.msg import QuaternionStamped
from rcl_interfaces.msg import ParameterType
from sensor_msgs.msg import Imu, MagneticField
from std_srvs.srv import Trigger
from test_nodes_node_base import RATE, motion, send
from test_nodes_parameters import get_params, set_param, started

from conftest import wait_for, wait_matched
from helpers_ros import quats, stamp_ns
from riann_ros.estimators import create
from riann_ros.magcal.input import MagConfig, pair_fields
from riann_ros.magcal.records import CALIBRATED, IDENTITY_9, STATES, UT, MagCalibration, MagCalPrior
from riann_ros.magcal.store import less_certain, load_calibration, save_calibration, to_yaml
from riann_ros.nodes.mag_calibration import SAVE_FORCE_SERVICE, SAVE_SERVICE, CalibrationFile
from riann_ros.nodes.vqf_node import VqfNode
from riann_ros.ros.services import call_service
from riann_ros.stream import EstimatorStream, GateConfig

pytestmark = pytest.mark.ros
H_UT = np.array([20.0, 0.0, -10.0])  # the robot's hard iron, in the raw field the node gets


def offline(name: str, stamps, acc, gyr, raw, sent, config: MagConfig, prior: MagCalPrior | None) -> np.ndarray:
    return offline_run(name, stamps, acc, gyr, raw, sent, config, prior)[0]


def offline_run(name: str, stamps, acc, gyr, raw, sent, config: MagConfig,
                prior: MagCalPrior | None) -> tuple[np.ndarray, EstimatorStream]:
    """The offline estimates and the stream after them (its ``batch_sigma``)."""
    fields = pair_fields(stamps, stamps[sent], raw[sent], config.timeout_ns)
    stream = EstimatorStream(create(name), GateConfig(nominal_rate=RATE), config, mag_prior=prior)
    assert stream.front is not None and stream.front.calibrating
    q, ok = stream.process_batch(stamps, acc, gyr, fields)
    assert ok.all()
    return q, stream


def run_node(ros, node, name: str, seconds: float, seed: int, t0_shift: int = 0, hard_iron_ut=H_UT):
    """Feed ``seconds`` of motion with a 100 Hz raw field (hard iron ``hard_iron_ut``); (stamps, acc, gyr, raw, sent,
    outputs, diagnostics)."""
    pub_imu, pub_mag = ros.publisher(Imu, "imu/data_raw"), ros.publisher(MagneticField, "imu/mag")
    att = ros.collect(QuaternionStamped, "imu/attitude" if name == "riann" else f"imu/{name}/attitude")
    diags = ros.collect(DiagnosticArray, "/diagnostics")
    wait_matched([pub_imu, pub_mag], [att], f"node to connect (log: {node.output()})")
    n = int(seconds * RATE)
    stamps, acc, gyr, mag = motion(n, seed)
    stamps = stamps + t0_shift
    raw = mag + hard_iron_ut * UT
    sent = send(ros, pub_imu, pub_mag, att, stamps, acc, gyr, raw, mag_until=n)
    wait_for(lambda: len(att.messages) >= n, 30, f"all outputs ({len(att.messages)} of {n}; log: {node.output()})")
    wait_for(lambda: len(diags.messages) >= 2, 10, "diagnostics")
    got = att.messages
    assert [stamp_ns(m) for m in got] == stamps.tolist()
    ros.destroy(pub_imu, pub_mag, att, diags)
    return stamps, acc, gyr, raw, sent, quats(got), diags.messages


def diag_values(messages, node_name: str) -> tuple[int, dict[str, str]]:
    s = [st for d in messages for st in d.status if st.name.startswith(node_name + ":")][-1]
    return s.level, {kv.key: kv.value for kv in s.values}


def trigger(ros, node_name: str, service: str) -> Trigger.Response:
    client = ros.node.create_client(Trigger, f"/{node_name}/{service.removeprefix('~/')}")
    assert client.wait_for_service(timeout_sec=10)
    res = call_service(client, Trigger.Request(), 10)
    ros.node.destroy_client(client)
    assert res is not None, f"no answer from {service}"
    return res


def save(ros, node_name: str) -> Trigger.Response:
    return trigger(ros, node_name, SAVE_SERVICE)


def equal_quats(a: np.ndarray, b: np.ndarray, tol: float = 1e-4) -> None:
    d = np.minimum(np.abs(a - b).max(axis=1), np.abs(a + b).max(axis=1))
    assert d.max() < tol, (d.max(), np.flatnonzero(d > tol)[:10])


def test_saved_once_loaded_at_the_next_start(ros, start_node, tmp_path):
    folder = tmp_path / "cal"
    folder.mkdir()
    path = folder / "my_mag.yaml"
    args = ("-p", "input_qos:=reliable", "-p", f"nominal_rate:={RATE}", "-p", f"mag_calibration_file:={path}",
            "-p", "diagnostics_period:=0.2")
    node = start_node("riann_node", *args)
    stamps, acc, gyr, raw, sent, q_node, diags = run_node(ros, node, "riann", 8.0, seed=1)
    assert "does not exist yet" in node.output()
    # over DDS the node equals the offline estimator with the calibration on (the default), from the parameters
    equal_quats(q_node, offline("riann", stamps, acc, gyr, raw, sent, MagConfig(), None))
    _, values = diag_values(diags, "riann_node")
    assert values["mag calibration"] in STATES and "/" in values["mag calibration windows (used / rejected)"]
    assert values["mag calibration file"] == f"{path} (not read at start)"
    res = save(ros, "riann_node")
    assert res.success, res.message
    assert res.message.startswith(f"wrote {path}: ") and "hard iron" in res.message
    cal = load_calibration(path)
    assert cal.windows > 0
    assert sorted(p.name for p in folder.iterdir()) == ["my_mag.yaml"]  # atomic: no temporary file left
    assert node.stop() == 0
    # the next start loads it: its hard and soft iron are the parameters, its estimate the calibration's start
    node2 = start_node("riann_node", *args)
    stamps2, acc2, gyr2, raw2, sent2, q_node2, diags2 = run_node(ros, node2, "riann", 6.0, seed=2,
                                                                 t0_shift=10**12)
    log = node2.output()
    assert f"mag_calibration_file {path} loaded: {cal.state}" in log
    config = MagConfig(mag_hard_iron=cal.hard_iron_t, mag_soft_iron=cal.soft_iron)
    q_off2, stream2 = offline_run("riann", stamps2, acc2, gyr2, raw2, sent2, config, MagCalPrior.from_calibration(cal))
    equal_quats(q_node2, q_off2)
    _, values2 = diag_values(diags2, "riann_node")
    assert values2["mag calibration file"] == f"{path} (loaded at start)"
    assert int(values2["mag calibration windows (used / rejected)"].split(" / ")[0]) >= cal.windows
    # saved again: the calibration in use is the file's, its hard iron widened by a new run's doubt
    # (RUN_TO_RUN_HARD_IRON_SD_UT) and narrowed by this run's windows that confirm it: more certain than the file, so
    # it replaces it (the refusal of a less certain one: test_the_save_service_never_downgrades_unless_forced)
    now = stream2.mag_calibration()
    assert now is not None and less_certain(now, cal) is None
    res2 = save(ros, "riann_node")
    assert res2.success, res2.message
    again = load_calibration(path)
    assert again.windows >= cal.windows and sum(v * v for v in again.hard_iron_sd_t) < sum(
        v * v for v in cal.hard_iron_sd_t)
    res3 = trigger(ros, "riann_node", SAVE_FORCE_SERVICE)
    assert res3.success and load_calibration(path).windows >= cal.windows


def test_a_bad_file_is_refused_and_never_replaced(ros, start_node, tmp_path):
    path = tmp_path / "my_params.yaml"
    text = "vqf_node:\n  ros__parameters:\n    tau_acc: 3.0\n"
    path.write_text(text)
    node = start_node("vqf_node", "-p", "input_qos:=reliable", "-p", f"nominal_rate:={RATE}",
                      "-p", f"mag_calibration_file:={path}", "-p", "diagnostics_period:=0.2")
    stamps, acc, gyr, raw, sent, q_node, diags = run_node(ros, node, "vqf", 3.0, seed=3, t0_shift=2 * 10**12)
    log = node.output()
    assert log.count("mag_calibration_file refused") == 1
    assert f"{path}: not a magnetometer calibration file" in log and "running on the parameters" in log
    equal_quats(q_node, offline("vqf", stamps, acc, gyr, raw, sent, MagConfig(), None))  # it runs on them
    level, values = diag_values(diags, "vqf_node")
    assert level == DiagnosticStatus.WARN and values["mag calibration file"].endswith("(refused at start: see the log)")
    assert values["mag calibration"] in STATES
    res = save(ros, "vqf_node")
    assert not res.success and "not a magnetometer calibration file" in res.message
    assert path.read_text() == text


@pytest.mark.parametrize("name", ["riann", "vqf"])
def test_reset_keeps_the_calibration_restart_starts_as_at_start(ros, start_node, name):
    """After a run that taught the online calibration the hard iron, ``~/reset`` keeps it (the next run equals an
    estimator that ran both, reset between) and ``~/restart`` forgets it (the next run equals a fresh estimator)."""
    node_name = f"{name}_node"
    node = start_node(node_name, "-p", "input_qos:=reliable", "-p", f"nominal_rate:={RATE}")
    first = run_node(ros, node, name, 8.0, seed=1)
    res = trigger(ros, node_name, "~/reset")
    assert res.success, res.message
    after_reset = run_node(ros, node, name, 3.0, seed=2, t0_shift=2 * 10**12)
    res = trigger(ros, node_name, "~/restart")
    assert res.success and "built anew" in res.message, res.message
    after_restart = run_node(ros, node, name, 3.0, seed=2, t0_shift=3 * 10**12)
    assert "restart requested" in node.output()
    assert node.stop() == 0
    fresh = run_node(ros, start_node(node_name, "-p", "input_qos:=reliable", "-p", f"nominal_rate:={RATE}"), name,
                     3.0, seed=2, t0_shift=3 * 10**12)

    def fields(run):
        stamps, acc, gyr, raw, sent = run[:5]
        return stamps, acc, gyr, pair_fields(stamps, stamps[sent], raw[sent], MagConfig().timeout_ns)

    kept = EstimatorStream(create(name), GateConfig(nominal_rate=RATE))
    kept.process_batch(*fields(first))
    cal = kept.mag_calibration()
    assert cal is not None and cal.windows > 0  # it learned the hard iron
    kept.reset()
    q_kept, ok = kept.process_batch(*fields(after_reset))
    assert ok.all()
    q_fresh = offline(name, *after_restart[:5], MagConfig(), None)
    equal_quats(after_reset[5], q_kept)
    equal_quats(after_restart[5], fresh[5], tol=1e-6)  # as a node just started, on the same input
    equal_quats(after_restart[5], q_fresh)
    # and the test tells the two apart: what the calibration learned moves the heading of the run after it
    d = np.minimum(np.abs(q_kept - q_fresh).max(axis=1), np.abs(q_kept + q_fresh).max(axis=1))
    assert d.max() > 1e-2, d.max()


def saved(path, hard_iron_ut: np.ndarray) -> MagCalibration:
    """A calibration file (riann_ros.magcal.store) holding ``hard_iron_ut`` known to 0.5 µT, 12 windows."""
    cov = np.diag(np.r_[np.full(9, 1e-4), np.full(3, (0.5 * UT) ** 2)])
    save_calibration(path, MagCalibration(hard_iron_t=tuple(hard_iron_ut * UT), soft_iron=IDENTITY_9,
                                          covariance=tuple(cov.reshape(144)), state=CALIBRATED, windows=12,
                                          converged_after_s=41.5, soft_iron_model="full"))
    return load_calibration(path)


def quat_distance(a: np.ndarray, b: np.ndarray) -> float:
    return float(np.minimum(np.abs(a - b).max(axis=1), np.abs(a + b).max(axis=1)).max())


def test_restart_starts_the_calibration_again_from_the_file_read_at_start(ros, start_node, tmp_path):
    """Started with ``mag_calibration_file``: after a run, ``~/restart`` and the next run equal an estimator started
    from that file (its hard and soft iron and how well it knows them: its imu/data's heading σ is the file's from the
    first field, not the wide one of the parameters alone); the file is left as it is."""
    folder = tmp_path / "cal"
    folder.mkdir()
    path = folder / "mag.yaml"
    cal = saved(path, H_UT)
    before = path.read_bytes(), path.stat().st_mtime_ns
    node = start_node("vqf_node", "-p", "input_qos:=reliable", "-p", f"nominal_rate:={RATE}",
                      "-p", f"mag_calibration_file:={path}")
    run_node(ros, node, "vqf", 6.0, seed=1)
    res = trigger(ros, "vqf_node", "~/restart")
    assert res.success, res.message
    imu_out = ros.collect(Imu, VqfNode.IMU_TOPIC)
    wait_matched([], [imu_out], VqfNode.IMU_TOPIC)
    stamps, acc, gyr, raw, sent, q_node, _ = run_node(ros, node, "vqf", 3.0, seed=2, t0_shift=3 * 10**12)
    wait_for(lambda: len(imu_out.messages) >= len(stamps), 10, VqfNode.IMU_TOPIC)
    assert (path.read_bytes(), path.stat().st_mtime_ns) == before  # restart leaves the file as it is
    assert [p.name for p in folder.iterdir()] == ["mag.yaml"]
    config = MagConfig(mag_hard_iron=cal.hard_iron_t, mag_soft_iron=cal.soft_iron)
    q_file, stream = offline_run("vqf", stamps, acc, gyr, raw, sent, config, MagCalPrior.from_calibration(cal))
    equal_quats(q_node, q_file)
    cov = np.array([m.orientation_covariance for m in imu_out.messages[-len(stamps):]])
    sigma = stream.batch_sigma
    np.testing.assert_allclose(cov[:, [0, 4, 8]], np.column_stack([sigma[:, 0], sigma[:, 0], sigma[:, 1]]) ** 2,
                               rtol=1e-4, atol=1e-6)
    # and the test tells the starts apart: the parameters without the file (another heading); the file's hard and
    # soft iron as parameters alone (the file's windows and covariance are not in the calibration then; the heading
    # σ is the same until this run's windows have tested the file: a saved calibration is trusted only so far)
    assert quat_distance(q_file, offline("vqf", stamps, acc, gyr, raw, sent, MagConfig(), None)) > 1e-2
    from_params = offline_run("vqf", stamps, acc, gyr, raw, sent, config, None)[1]
    with_file, without = stream.mag_cal_status(), from_params.mag_cal_status()
    assert with_file is not None and without is not None and with_file.windows >= cal.windows > without.windows


def test_restart_starts_the_calibration_again_from_mag_hard_iron_set_since(ros, start_node, tmp_path):
    """The robot's hard iron moved (H2) since its file was saved (H_UT) and ``mag_hard_iron`` is set to H2 at run
    time: after a run, ``~/restart`` and the next run equal an estimator started from H2 (not from the file, whose
    values replaced the parameters at start, nor from the parameter as given)."""
    h2_ut = np.array([-15.0, 10.0, 5.0])
    folder = tmp_path / "cal"
    folder.mkdir()
    cal = saved(folder / "mag.yaml", H_UT)
    node = start_node("vqf_node", "-p", "input_qos:=reliable", "-p", f"nominal_rate:={RATE}",
                      "-p", f"mag_calibration_file:={folder / 'mag.yaml'}")
    assert set_param(ros, "/vqf_node", "mag_hard_iron", tuple(h2_ut * UT)) == (True, "")
    config = MagConfig(mag_hard_iron=tuple(h2_ut * UT), mag_soft_iron=cal.soft_iron)
    first = run_node(ros, node, "vqf", 3.0, seed=1, hard_iron_ut=h2_ut)
    equal_quats(first[5], offline("vqf", *first[:5], config, None))  # the set restarted the calibration from H2
    res = trigger(ros, "vqf_node", "~/restart")
    assert res.success, res.message
    stamps, acc, gyr, raw, sent, q_node, _ = run_node(ros, node, "vqf", 3.0, seed=2, t0_shift=3 * 10**12,
                                                      hard_iron_ut=h2_ut)
    q_h2 = offline("vqf", stamps, acc, gyr, raw, sent, config, None)
    equal_quats(q_node, q_h2)
    # and the test tells it from the file's start (the values at start) and from the parameter as given (the default,
    # which the file replaced)
    at_start = MagConfig(mag_hard_iron=cal.hard_iron_t, mag_soft_iron=cal.soft_iron)
    q_file = offline("vqf", stamps, acc, gyr, raw, sent, at_start, MagCalPrior.from_calibration(cal))
    assert quat_distance(q_h2, q_file) > 1e-2
    assert quat_distance(q_h2, offline("vqf", stamps, acc, gyr, raw, sent, MagConfig(), None)) > 1e-2


# ---- files and values that are no calibration: one WARN, the node runs on its parameters, never an exit or a hang --
def _doc_file(path, change) -> str:
    """A calibration file with ``change`` applied to its YAML document (written as text: the store writes no
    calibration validation refuses)."""
    cov = np.diag(np.r_[np.full(9, 1e-4), np.full(3, (0.5 * UT) ** 2)])
    doc = yaml.safe_load(to_yaml(MagCalibration(hard_iron_t=tuple(H_UT * UT), soft_iron=IDENTITY_9,
                                                covariance=tuple(cov.reshape(144)), state=CALIBRATED, windows=12,
                                                converged_after_s=41.5, soft_iron_model="full")))
    change(doc)
    path.write_text(yaml.safe_dump(doc))
    return str(path)


def _fifo(path) -> str:
    os.mkfifo(path)
    return str(path)


def _folder(path) -> str:
    path.mkdir()
    return str(path)


def _huge(path) -> str:
    with path.open("wb") as f:  # 4 GiB, sparse
        f.truncate(4 << 30)
    return str(path)


#: the issue's list: (how to make it, what the refusal says)
BAD_FILES = {
    "covariance_1e308": (lambda p: _doc_file(p, lambda d: d["mag_calibration"].update(covariance=[1e308] * 144)),
                         "covariance: a standard deviation is over its bound"),
    "hard_iron_999uT": (lambda p: _doc_file(p, lambda d: d.update(mag_hard_iron=[999e-6, 0.0, 0.0])),
                        "mag_hard_iron |h| = 999 µT is over 933 µT"),
    "soft_iron_reflection": (lambda p: _doc_file(p, lambda d: d.update(mag_soft_iron=[-1, 0, 0, 0, -1, 0, 0, 0, 1])),
                             "mag_soft_iron holds a rotation of 180.0°"),
    "soft_iron_1500": (lambda p: _doc_file(p, lambda d: d.update(mag_soft_iron=[1500, 0, 0, 0, 1500, 0, 0, 0, 1500])),
                       "mag_soft_iron scales the field by 1500–1500"),
    "fifo": (_fifo, "is a FIFO (named pipe), not a calibration file (not read)"),
    "dev_zero": (lambda p: "/dev/zero", "is a character device, not a calibration file (not read)"),
    "folder": (_folder, "is a folder, not a calibration file (not read)"),
    "huge": (_huge, f"is {4 << 30} bytes, over the 64 KiB a calibration file can be (not read)"),
}


@pytest.mark.parametrize(("name", "bad"), [("riann", "covariance_1e308"), ("vqf", "covariance_1e308"),
                                           ("vqf", "hard_iron_999uT"), ("riann", "soft_iron_reflection"),
                                           ("vqf", "soft_iron_1500"), ("riann", "fifo"), ("vqf", "dev_zero"),
                                           ("vqf", "folder"), ("vqf", "huge")])
def test_a_file_that_is_no_calibration_is_refused_and_the_node_runs(ros, start_node, tmp_path, name, bad):
    make, reason = BAD_FILES[bad]
    path = make(tmp_path / "mag.yaml")
    # what the node runs at start, timed: it returns (no hang) within 1 s, with one warning
    box: dict = {}
    reader = threading.Thread(target=lambda: box.update(file=CalibrationFile(path)), daemon=True)
    t0 = time.monotonic()
    reader.start()
    reader.join(1.0)
    assert not reader.is_alive(), f"reading {path} did not return within 1 s"
    assert time.monotonic() - t0 < 1.0
    assert [level for level, _ in box["file"].log] == ["warning"] and box["file"].loaded is None
    node = start_node(f"{name}_node", "-p", "input_qos:=reliable", "-p", f"nominal_rate:={RATE}",
                      "-p", f"mag_calibration_file:={path}", "-p", "diagnostics_period:=0.2")
    stamps, acc, gyr, raw, sent, q_node, diags = run_node(ros, node, name, 2.0, seed=4)
    log = node.output()
    assert log.count("mag_calibration_file refused") == 1 and log.count("WARN") == 1, log
    assert f"mag_calibration_file refused: {path}: {reason}" in log and "running on the parameters" in log
    equal_quats(q_node, offline(name, stamps, acc, gyr, raw, sent, MagConfig(), None))  # on its parameters
    level, values = diag_values(diags, f"{name}_node")
    assert level == DiagnosticStatus.WARN and values["mag calibration file"].endswith("(refused at start: see the log)")
    assert node.stop() == 0  # SIGINT ends it at once (a node blocked on a FIFO ignored it)
    if bad == "fifo":
        assert stat.S_ISFIFO(os.stat(path).st_mode)  # left as it was


def test_refused_parameter_values_at_start_and_at_run_time(ros, start_node):
    """At start a refused ``mag_hard_iron`` / ``mag_soft_iron`` is replaced by its default (one WARN each); at run time
    a refused value is not applied (the set fails with the reason, one WARN) and the value in use stays."""
    node = start_node("vqf_node", "-p", "input_qos:=reliable", "-p", f"nominal_rate:={RATE}",
                      "-p", "mag_soft_iron:=[-1.0, 0.0, 0.0, 0.0, -1.0, 0.0, 0.0, 0.0, 1.0]",
                      "-p", "mag_hard_iron:=[0.000999, 0.0, 0.0]")
    stamps, acc, gyr, raw, sent, q_node, _ = run_node(ros, node, "vqf", 2.0, seed=5)
    log = node.output()
    assert log.count("WARN") == 2, log
    assert ("parameter mag_soft_iron = [-1.0, 0.0, 0.0, 0.0, -1.0, 0.0, 0.0, 0.0, 1.0] refused: mag_soft_iron holds a "
            "rotation of 180.0°") in log
    assert "the node runs on its default [1.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 1.0]" in log
    assert "parameter mag_hard_iron = [0.000999, 0.0, 0.0] refused: mag_hard_iron |h| = 999 µT" in log
    assert get_params(ros, "/vqf_node", ["mag_hard_iron", "mag_soft_iron"]) == {
        "mag_hard_iron": (ParameterType.PARAMETER_DOUBLE_ARRAY, (0.0, 0.0, 0.0)),
        "mag_soft_iron": (ParameterType.PARAMETER_DOUBLE_ARRAY, IDENTITY_9)}
    equal_quats(q_node, offline("vqf", stamps, acc, gyr, raw, sent, MagConfig(), None))
    ok, reason = set_param(ros, "/vqf_node", "mag_soft_iron", (6.0, 0.0, 0.0, 0.0, 6.0, 0.0, 0.0, 0.0, 6.0))
    assert not ok and reason.startswith("mag_soft_iron refused: mag_soft_iron scales the field by 6–6")
    assert reason.endswith("(the value in use stays)")
    wait_for(lambda: node.output().count("WARN") == 3, 5, "the warning")
    assert f"parameters not changed: {reason}" in node.output()
    assert get_params(ros, "/vqf_node", ["mag_soft_iron"])["mag_soft_iron"][1] == IDENTITY_9
    assert set_param(ros, "/vqf_node", "mag_hard_iron", (20e-6, 0.0, -10e-6)) == (True, "")  # a good one is taken


def test_the_save_service_never_downgrades_unless_forced(ros, start_node, tmp_path):
    """Started with a calibrated file and given no data, ``~/save_mag_calibration`` keeps the file as it was (bytes,
    mode, time) and says so; ``~/save_mag_calibration_force`` replaces it, keeping its mode. A temporary file a cut-off
    save left beside it is removed at the start."""
    folder = tmp_path / "cal"
    folder.mkdir()
    path = folder / "mag.yaml"
    saved(path, H_UT)
    os.chmod(path, 0o640)
    left = folder / ".mag.yaml.0badc0de.tmp"
    left.write_text("half a calibra")
    before = path.read_bytes(), path.stat().st_mode, path.stat().st_mtime_ns
    node = start_node("riann_node", "-p", f"mag_calibration_file:={path}")
    started(node)
    res = save(ros, "riann_node")
    assert f"removed {left}: a temporary file left by a save of {path} that was cut off" in node.output()
    assert [p.name for p in folder.iterdir()] == ["mag.yaml"]
    assert not res.success
    assert res.message == (f"kept the file: the current calibration adds no window of rotation to the 12 of the file "
                           f"loaded at start; {path} not written (~/save_mag_calibration_force replaces it)")
    assert (path.read_bytes(), path.stat().st_mode, path.stat().st_mtime_ns) == before
    res = trigger(ros, "riann_node", SAVE_FORCE_SERVICE)
    assert res.success and res.message.startswith(f"wrote {path}: converging, hard iron"), res.message
    assert load_calibration(path).state == "converging" and (path.stat().st_mode & 0o777) == 0o640
    assert [p.name for p in folder.iterdir()] == ["mag.yaml"]
    assert f"{SAVE_FORCE_SERVICE}: wrote {path}" in node.output()
    assert node.stop() == 0  # a refusal then a write (a warning, then an info) leave it running
