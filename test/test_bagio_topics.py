"""evo-style scoring of what is already in a bag: --estimate-topic, --ground-truth-topic, --imu-topic, --t-offset."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest
from test_evaluation import synthetic

from riann_ros import defaults
from riann_ros import evaluation as ev
from riann_ros import quaternion as quat
from riann_ros.cli.evaluate import main
from riann_ros.recording import Recording

bagio = pytest.importorskip("riann_ros.bagio")
from riann_ros.bagio import topics as tp  # noqa: E402

T0 = 1_700_000_000_000_000_000


def noisy(name: str = "seq", rate: float = 200.0, move_s: float = 20.0) -> Recording:
    """test_evaluation.synthetic with sensor noise, so the filters have something to do."""
    rec = synthetic(rate=rate, move_s=move_s, name=name, t0_ns=T0)
    rng = np.random.default_rng(1)
    rec.gyr = rec.gyr + rng.normal(0, 0.005, rec.gyr.shape)
    rec.acc = rec.acc + rng.normal(0, 0.05, rec.acc.shape)
    return rec


# -- writing bags the way other tools do -----------------------------------------------------------------
def _ts():
    return bagio.typestore()


def _header(stamp: int, frame: str):
    ts = _ts()
    sec, nsec = divmod(int(stamp), 1_000_000_000)
    return ts.types["std_msgs/msg/Header"](stamp=ts.types["builtin_interfaces/msg/Time"](sec=sec, nanosec=nsec),
                                           frame_id=frame)


def _quat_obj(q):
    return _ts().types["geometry_msgs/msg/Quaternion"](w=float(q[0]), x=float(q[1]), y=float(q[2]), z=float(q[3]))


def imu_msg(stamp: int, acc=(0.0, 0.0, 9.81), gyr=(0.0, 0.0, 0.0), q=None, ocov=None):
    ts = _ts()
    v3 = ts.types["geometry_msgs/msg/Vector3"]
    ocov = np.zeros(9) if ocov is None else np.asarray(ocov, dtype=np.float64)
    if q is None:
        ocov[0] = -1.0
        q = (1.0, 0.0, 0.0, 0.0)
    return ts.types["sensor_msgs/msg/Imu"](
        header=_header(stamp, "imu"), orientation=_quat_obj(q), orientation_covariance=ocov,
        angular_velocity=v3(x=float(gyr[0]), y=float(gyr[1]), z=float(gyr[2])), angular_velocity_covariance=np.zeros(9),
        linear_acceleration=v3(x=float(acc[0]), y=float(acc[1]), z=float(acc[2])),
        linear_acceleration_covariance=np.zeros(9))


def pose_msg(stamp: int, q):
    ts = _ts()
    pose = ts.types["geometry_msgs/msg/Pose"](position=ts.types["geometry_msgs/msg/Point"](x=1.0, y=2.0, z=0.5),
                                              orientation=_quat_obj(q))
    return ts.types["geometry_msgs/msg/PoseStamped"](header=_header(stamp, "mocap"), pose=pose)


def odom_msg(stamp: int, q, cov=None):
    ts = _ts()
    pose = ts.types["geometry_msgs/msg/Pose"](position=ts.types["geometry_msgs/msg/Point"](x=0.0, y=0.0, z=0.0),
                                              orientation=_quat_obj(q))
    cov = np.zeros(36) if cov is None else np.asarray(cov, dtype=np.float64)
    pwc = ts.types["geometry_msgs/msg/PoseWithCovariance"](pose=pose, covariance=cov)
    tw = ts.types["geometry_msgs/msg/Twist"](linear=ts.types["geometry_msgs/msg/Vector3"](x=0.0, y=0.0, z=0.0),
                                             angular=ts.types["geometry_msgs/msg/Vector3"](x=0.0, y=0.0, z=0.0))
    twc = ts.types["geometry_msgs/msg/TwistWithCovariance"](twist=tw, covariance=np.zeros(36))
    return ts.types["nav_msgs/msg/Odometry"](header=_header(stamp, "odom"), child_frame_id="base_link", pose=pwc,
                                             twist=twc)


def write_bag(path: Path, topics: dict[str, tuple[str, list[tuple[int, object]]]],
              copy_from: Path | None = None) -> Path:
    """A directory bag (MCAP storage) with ``topics[name] = (msgtype, [(log time, message)])``, plus every message of
    ``copy_from``; messages in log-time order."""
    from rosbags.rosbag2 import Reader, StoragePlugin, Writer

    ts = _ts()
    rows: list[tuple[int, int, object, bytes]] = []
    with Writer(path, version=9, storage_plugin=StoragePlugin.MCAP) as w:
        if copy_from is not None:
            with Reader(copy_from) as r:
                conns = {c.id: w.add_connection(c.topic, c.msgtype, typestore=ts) for c in r.connections}
                rows += [(t, 0, conns[c.id], raw) for c, t, raw in r.messages()]
        for k, (topic, (msgtype, msgs)) in enumerate(topics.items(), 1):
            conn = w.add_connection(topic, msgtype, typestore=ts)
            rows += [(t, k, conn, bytes(ts.serialize_cdr(m, msgtype))) for t, m in msgs]
        for t, _, conn, raw in sorted(rows, key=lambda r: (r[0], r[1])):
            w.write(conn, t, raw)
    return path


# -- acceptance: a filter's estimates recorded in the bag score like the filter run in-process ----------
@pytest.fixture(scope="module")
def copy_with_estimates(tmp_path_factory) -> tuple[Path, Path]:
    """A converter bag; its copy from --write-estimates (QuaternionStamped /eval/as_recorded/<estimator> at the IMU
    stamps) plus Imu-typed estimate topics: /my_filter/imu (madgwick's, every sample) and /late/imu (every other
    sample, stamped 0.5 s early, logged 3 ms late)."""
    d = tmp_path_factory.mktemp("recorded")
    rec = noisy()
    bag = bagio.write_recording(d / "seq.mcap", rec)
    est_dir = d / "est"
    assert main([str(bag), "-e", "madgwick,vqf", "-s", "as-recorded", "--write-estimates", str(est_dir), "-q"]) == 0
    copy = est_dir / "seq.mcap"
    settings = ev.EvalSettings(estimators=ev.parse_estimators("madgwick"), scenarios=[ev.AS_RECORDED],
                               keep_estimates=True)
    res = ev.evaluate_source(bag, settings)
    stamps, q = res.estimates["stamps"], res.estimates["quats"]["madgwick"]
    ok = np.isfinite(q).all(axis=1)
    imu = [(int(s), imu_msg(int(s), q=qq)) for s, qq in zip(stamps[ok], q[ok], strict=True)]
    late = [(int(s) + 3_000_000, imu_msg(int(s) - 500_000_000, q=qq))
            for s, qq in zip(stamps[ok][::2], q[ok][::2], strict=True)]
    # madgwick's estimates with the covariance madgwick_node publishes: its documented constants
    sd = np.radians([defaults.INCLINATION_SD_DEG, defaults.INCLINATION_SD_DEG, defaults.YAW_FREE_SD_DEG])
    cov = [(int(s), imu_msg(int(s), q=qq, ocov=np.diag(sd**2).ravel())) for s, qq in zip(stamps[ok], q[ok],
                                                                                        strict=True)]
    full = write_bag(d / "with_imu_estimates", {"/my_filter/imu": ("sensor_msgs/msg/Imu", imu),
                                                  "/late/imu": ("sensor_msgs/msg/Imu", late),
                                                  "/cov/imu": ("sensor_msgs/msg/Imu", cov)}, copy_from=copy)
    return bag, full


@pytest.mark.slow
def test_recorded_estimates_score_like_the_filter_in_process(copy_with_estimates, tmp_path, capsys):
    _, full = copy_with_estimates
    out = tmp_path / "out"
    rc = main([str(full), "-e", "madgwick,vqf", "--estimate-topic", "/eval/as_recorded/madgwick",
               "--estimate-topic", "/eval/as_recorded/vqf", "--estimate-topic", "/my_filter/imu", "--out", str(out),
               "--no-plots", "-q"])
    assert rc == 0
    text = capsys.readouterr().out
    assert "/my_filter/imu" in text
    rows = json.loads((out / "results.json").read_text())["results"]
    got = {(r["scenario"], r["estimator"]): r for r in rows}
    for label, topics in (("madgwick", ("/eval/as_recorded/madgwick", "/my_filter/imu")),
                          ("vqf", ("/eval/as_recorded/vqf",))):
        own = got[("as-recorded", label)]
        for topic in topics:
            r = got[("as-recorded", topic)]
            assert r["rmse_deg"] == pytest.approx(own["rmse_deg"], abs=0.01), topic
            assert r["n_scored"] == own["n_scored"] and r["mode"] == "recorded" and r["estimator_name"] == "recorded"
    # recorded estimates exist only for the recording as it is
    assert {r["estimator"] for r in rows if r["scenario"] != "as-recorded"} == {"madgwick", "vqf"}


@pytest.mark.slow
def test_t_offset_decimated_and_late_estimates(copy_with_estimates, capsys):
    _, full = copy_with_estimates
    settings = ev.EvalSettings(estimators=ev.parse_estimators("madgwick"), scenarios=[ev.AS_RECORDED],
                               topics=ev.BagTopics(estimates=("/late/imu",), t_offset_s=0.5))
    res = ev.evaluate_source(full, settings)
    assert res.error is None
    own, late = res.rows
    assert late.estimator == "/late/imu" and late.score.n_unestimated == 0
    assert late.rmse_deg == pytest.approx(own.rmse_deg, abs=0.02)  # every other sample is a slerp
    # without the offset every sample gets the estimate of 0.5 s later
    settings.topics = ev.BagTopics(estimates=("/late/imu",))
    _, shifted = ev.evaluate_source(full, settings).rows
    assert shifted.rmse_deg > own.rmse_deg + 5.0
    # stamps of another clock: no message near any sample, a clear error naming --t-offset
    assert main([str(full), "-e", "madgwick", "--estimate-topic", "/late/imu", "--t-offset", "1000", "-q"]) == 1
    err = capsys.readouterr().err
    assert "recorded estimate /late/imu: no estimate near any scored sample" in err and "--t-offset" in err


def test_a_recorded_covariance_is_scored_like_the_estimator_in_process(copy_with_estimates):
    """The σ of an estimate topic's orientation_covariance gets the uncertainty scores (NEES, coverage) the same
    estimator's in-process σ gets; a topic whose covariance is all zero (unknown) gets none."""
    _, full = copy_with_estimates
    settings = ev.EvalSettings(estimators=ev.parse_estimators("madgwick"), scenarios=[ev.AS_RECORDED],
                               topics=ev.BagTopics(estimates=("/cov/imu", "/my_filter/imu")))
    res = ev.evaluate_source(full, settings)
    assert res.error is None
    own, cov, unknown = res.rows
    assert cov.estimator == "/cov/imu" and unknown.estimator == "/my_filter/imu"
    mine, theirs = own.score, cov.score
    assert mine.nees is not None and mine.nees > 0.0
    assert theirs.nees == pytest.approx(mine.nees, rel=1e-3)
    assert theirs.cover95_pct == pytest.approx(mine.cover95_pct, abs=0.2)
    assert unknown.score.nees is None and unknown.score.cover95_pct is None


def test_parse_orientations_sigma_from_the_covariance():
    ts = _ts()
    qs = quat.from_rotvec(np.array([[0.1, 0.2, 0.3], [0.0, 0.0, 0.0], [-0.3, 0.1, 0.0]]))
    imu_cov = np.diag([0.01, 0.03, 0.25]).ravel()  # rad²: inclination σ √0.02, heading σ 0.5
    pose_cov = np.zeros((6, 6))
    pose_cov[3:, 3:] = np.diag([0.01, 0.03, 0.25])
    pose_cov[0, 0] = 99.0  # position variance: not an orientation's
    want = np.array([np.sqrt(0.02), 0.5])
    for msgtype, make in (("sensor_msgs/msg/Imu", lambda s, q: imu_msg(s, q=q, ocov=imu_cov)),
                          ("nav_msgs/msg/Odometry", lambda s, q: odom_msg(s, q, cov=pose_cov.ravel()))):
        raws = [bytes(ts.serialize_cdr(make(T0 + k, q), msgtype)) for k, q in enumerate(qs)]
        _, got = tp.parse_orientations(raws, msgtype, sigma=True)
        np.testing.assert_allclose(got[:, :4], qs, atol=1e-15)
        np.testing.assert_allclose(got[:, 4:], np.tile(want, (3, 1)), rtol=1e-12)
        m = make(T0, qs[0])
        m.header.frame_id = "another_frame"  # other length: the generic path gives the same
        _, got2 = tp.parse_orientations([*raws, bytes(ts.serialize_cdr(m, msgtype))], msgtype, sigma=True)
        np.testing.assert_allclose(got2[:, 4:], np.tile(want, (4, 1)), rtol=1e-12)
    # no covariance: an all-zero one (ROS: unknown), a type without one, a negative variance
    negative = np.diag([0.01, -1e-3, 0.1]).ravel()
    for msgtype, make in (("sensor_msgs/msg/Imu", lambda s, q: imu_msg(s, q=q, ocov=np.zeros(9))),
                          ("geometry_msgs/msg/PoseStamped", pose_msg),
                          ("sensor_msgs/msg/Imu", lambda s, q: imu_msg(s, q=q, ocov=negative))):
        _, got = tp.parse_orientations([bytes(ts.serialize_cdr(make(T0, qs[0]), msgtype))], msgtype, sigma=True)
        assert np.isfinite(got[0, :4]).all() and np.isnan(got[0, 4:]).all(), msgtype
    # σ between two messages: linear where the orientation is slerped
    st = np.array([0, 10], np.int64)
    rows = np.hstack([np.vstack([qs[1], qs[1]]), np.array([[0.1, 1.0], [0.3, 2.0]])])
    np.testing.assert_allclose(tp.interpolate(st, rows, np.array([5], np.int64), 20)[0, 4:], [0.2, 1.5])


def test_estimators_none_scores_only_the_recorded_topic(copy_with_estimates, tmp_path):
    _, full = copy_with_estimates
    out = tmp_path / "only"
    assert main([str(full), "-e", "none", "--estimate-topic", "my_filter/imu", "--out", str(out), "--no-plots",
                 "-q"]) == 0
    data = json.loads((out / "results.json").read_text())
    assert [(r["scenario"], r["estimator"]) for r in data["results"]] == [("as-recorded", "/my_filter/imu")]
    assert data["settings"]["scenarios"] == ["as-recorded"]


def test_recorded_topics_usage_errors(copy_with_estimates, capsys):
    _, full = copy_with_estimates
    assert main([str(full), "--estimate-topic", "/my_filter/imu", "-s", "realistic"]) == 2
    assert "as-recorded scenario" in capsys.readouterr().err
    assert main([str(full), "--estimate-topic", "/my_filter/imu", "--rates", "100"]) == 2
    assert "native in --rates" in capsys.readouterr().err
    assert main([str(full), "--estimate-topic", "/my_filter/imu", "-p", "rate:50"]) == 2
    assert "none in --perturb" in capsys.readouterr().err
    assert main([str(full), "-e", "none"]) == 2
    assert main([str(full), "--estimate-topic", "/x", "--max-gap", "0"]) == 2
    assert main([str(full), "-e", "madgwick", "--estimate-topic", "/nope", "-q"]) == 1
    err = capsys.readouterr().err
    assert "no /nope topic (topics:" in err and "/my_filter/imu" in err
    assert main([str(full), "-e", "madgwick", "--estimate-topic", "/ground_truth/scored", "-q"]) == 1
    assert "has type std_msgs/msg/Bool; an orientation topic must be one of" in capsys.readouterr().err


# -- a bag from elsewhere -------------------------------------------------------------------------------
def foreign_bag(path: Path, rec: Recording, gt_rate: float = 120.0, gt_latency_ns: int = 4_000_000,
                gt_type: str = "pose") -> Path:
    """Imu on /imu (no score topic, no /dataset/info) and the reference on /mocap/pose as PoseStamped (or on /odom
    as Odometry) at ``gt_rate`` Hz from its own clock (stamps between the IMU's), logged ``gt_latency_ns`` late."""
    imu = [(int(s), imu_msg(int(s), a, g)) for s, a, g in zip(rec.stamps_ns, rec.acc, rec.gyr, strict=True)]
    t_gt = np.arange(rec.stamps_ns[0] + 1_234_567, rec.stamps_ns[-1], round(1e9 / gt_rate), dtype=np.int64)
    q_gt = ev_slerp(rec, t_gt)
    make = pose_msg if gt_type == "pose" else odom_msg
    gt = [(int(s) + gt_latency_ns, make(int(s), q)) for s, q in zip(t_gt, q_gt, strict=True)]
    topic, msgtype = ("/mocap/pose", "geometry_msgs/msg/PoseStamped") if gt_type == "pose" else (
        "/odom", "nav_msgs/msg/Odometry")
    return write_bag(path, {"/imu": ("sensor_msgs/msg/Imu", imu), topic: (msgtype, gt)})


def ev_slerp(rec: Recording, t: np.ndarray) -> np.ndarray:
    """The recording's reference at stamps ``t`` (slerp)."""
    return tp.interpolate(rec.stamps_ns, rec.quat_ref, t, 10**9)


@pytest.mark.slow
@pytest.mark.parametrize("gt_type", ["pose", "odom"])
def test_foreign_bag_with_a_ground_truth_topic(tmp_path, gt_type, capsys):
    rec = noisy(name="foreign", move_s=15.0)
    rec.score_mask[:] = True  # a foreign bag has no score topic: everything is scored
    layout = bagio.write_recording(tmp_path / "layout.mcap", rec)
    foreign = foreign_bag(tmp_path / "foreign_bag", rec, gt_type=gt_type)
    topic = "/mocap/pose" if gt_type == "pose" else "/odom"
    out = tmp_path / "out"
    rc = main([str(foreign), "--imu-topic", "/imu", "--ground-truth-topic", topic, "-e", "madgwick,vqf", "-s",
               "as-recorded,restrictive", "--out", str(out), "--no-plots", "-q"])
    assert rc == 0
    assert "no rest found before the first scored sample" in capsys.readouterr().err  # all scored: no unscored span
    got = json.loads((out / "results.json").read_text())
    assert got["sequences"][0]["name"] == "foreign_bag"
    ref = ev.evaluate_source(layout, ev.EvalSettings(estimators=ev.parse_estimators("madgwick,vqf"),
                                                     scenarios=[ev.AS_RECORDED, ev.RESTRICTIVE]))
    want = {(r.scenario, r.estimator): r for r in ref.rows}
    for r in got["results"]:
        w = want[(r["scenario"], r["estimator"])]
        # the reference slerped from 120 Hz onto the IMU stamps: the first 1.2 ms have none (held within max-gap/2)
        assert r["n_scored"] == w.score.n_scored
        assert r["rmse_deg"] == pytest.approx(w.rmse_deg, abs=0.01)


def test_foreign_bag_chunked_equals_whole(tmp_path):
    rec = noisy(name="chunks", move_s=10.0)
    foreign = foreign_bag(tmp_path / "f", rec, gt_rate=97.0)
    topics = ev.BagTopics(imu="/imu", reference="/mocap/pose")
    base = {"estimators": ev.parse_estimators("madgwick"), "scenarios": list(ev.SCENARIOS), "topics": topics,
            "series_for": "*"}
    small = ev.evaluate_source(foreign, ev.EvalSettings(**base, chunk=97))
    whole = ev.evaluate_source(foreign, ev.EvalSettings(**base, chunk=10**6))
    assert small.error is None and whole.error is None
    assert small.scenarios == whole.scenarios
    for a, b in zip(small.rows, whole.rows, strict=True):
        assert a.rmse_deg == pytest.approx(b.rmse_deg, abs=1e-9) and a.score.n_scored == b.score.n_scored


def test_ground_truth_topic_on_a_broad_file_is_refused(tmp_path):
    f = tmp_path / "x.hdf5"
    f.write_bytes(b"")
    res = ev.evaluate_source(f, ev.EvalSettings(estimators=ev.parse_estimators("madgwick"),
                                                topics=ev.BagTopics(reference="/pose")))
    assert "apply to bags only" in res.error


# -- alignment ------------------------------------------------------------------------------------------
def test_interpolate_rules():
    st = np.array([0, 10, 20, 200], dtype=np.int64) * 1_000_000  # ms
    q = quat.from_rotvec(np.array([[0.0, 0, 0], [0.1, 0, 0], [0.2, 0, 0], [0.3, 0, 0]]))
    t = np.array([-60, -40, 0, 5, 20, 30, 60, 140, 170, 260], dtype=np.int64) * 1_000_000
    out = tp.interpolate(st, q, t, 100_000_000)  # max gap 100 ms: hold within 50 ms
    angle = 2 * np.arctan2(out[:, 1], out[:, 0])
    np.testing.assert_allclose(angle[1:7], [0.0, 0.0, 0.05, 0.2, 0.2, 0.2], atol=1e-12)
    # -60: > 50 ms before the first; -40: held; 5: slerp; 30, 60: 20..200 is a 180 ms gap → hold the nearer (20)
    # within 50 ms; 140: in the gap, > 50 ms from both; 170: 30 ms before 200 → held; 260: > 50 ms after the last
    assert np.isnan(out[[0, 7, 9], 0]).all()
    assert angle[8] == pytest.approx(0.3)
    assert np.isnan(tp.interpolate(st[:0], q[:0], t, 10**8)).all()


def test_aligner_memory_stays_bounded_and_serves_chunks():
    n = 20_000
    st = np.arange(n, dtype=np.int64) * 5_000_000  # 200 Hz for 100 s
    q = quat.from_rotvec(np.column_stack([np.linspace(0, 1, n), np.zeros(n), np.zeros(n)]))
    batches = ((st[a:a + 512], q[a:a + 512]) for a in range(0, n, 512))
    al = tp.Aligner(batches, offset_ns=0, max_gap_ns=100_000_000)
    sizes, got = [], []
    for a in range(0, n, 1000):
        got.append(al.at(st[a:a + 1000] + 1_000_000))  # 1 ms after each message: slerp
        sizes.append(len(al.st))
    assert max(sizes) < 2 * 512 + 40  # a batch or two and the max-gap window, not the topic
    out = np.concatenate(got)
    assert np.isfinite(out[:-1]).all()
    np.testing.assert_allclose(np.abs(np.sum(out[:-1] * quat.slerp(q[:-1], q[1:], 0.2), axis=1)), 1.0, atol=1e-12)
    assert al.messages == n


def test_parse_orientations_fast_and_generic_paths():
    ts = _ts()
    qs = quat.from_rotvec(np.array([[0.1, 0.2, 0.3], [0.0, 0.0, 0.0], [-0.3, 0.1, 0.0]]))
    for msgtype, make in (("geometry_msgs/msg/PoseStamped", pose_msg), ("nav_msgs/msg/Odometry", odom_msg),
                          ("sensor_msgs/msg/Imu", lambda s, q: imu_msg(s, q=q))):
        raws = [bytes(ts.serialize_cdr(make(T0 + k, q), msgtype)) for k, q in enumerate(qs)]
        st, got = tp.parse_orientations(raws, msgtype)
        np.testing.assert_array_equal(st, T0 + np.arange(3))
        np.testing.assert_allclose(got, qs, atol=1e-15)
        m = make(T0, qs[0])
        m.header.frame_id = "another_frame"  # other length: the generic path
        _, got2 = tp.parse_orientations([*raws, bytes(ts.serialize_cdr(m, msgtype))], msgtype)
        np.testing.assert_allclose(got2, np.vstack([qs, qs[:1]]), atol=1e-15)
    raw = [bytes(ts.serialize_cdr(imu_msg(T0), "sensor_msgs/msg/Imu"))]  # orientation_covariance[0] = -1
    assert np.isnan(tp.parse_orientations(raw, "sensor_msgs/msg/Imu")[1]).all()
