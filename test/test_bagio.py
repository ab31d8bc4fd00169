"""Bag layout, round trips, atomic writes and BagError cases of riann_ros.bagio (no BROAD needed)."""

from __future__ import annotations

import sqlite3
from pathlib import Path

import numpy as np
import pytest

from riann_ros import bagio
from riann_ros.datasets.synthetic import generate
from riann_ros.evaluation.magpair import NodePairing
from riann_ros.magcal.input import MagConfig, pair_fields
from riann_ros.recording import Recording


def _rec(n: int = 500, seed: int = 0, with_ref: bool = True) -> Recording:
    rng = np.random.default_rng(seed)
    stamps = 1_700_000_000_000_000_000 // 1000 + np.cumsum(rng.integers(4_000_000, 6_000_000, n))
    q = rng.normal(size=(n, 4))
    q /= np.linalg.norm(q, axis=1, keepdims=True)
    q[rng.random(n) < 0.1] = np.nan
    mask = np.zeros(n, dtype=bool)
    mask[n // 5 : n // 2] = True
    mask[3 * n // 4 :] = True
    return Recording(
        stamps_ns=stamps,
        acc=rng.normal(size=(n, 3)) * 5,
        gyr=rng.normal(size=(n, 3)),
        quat_ref=q if with_ref else None,
        score_mask=mask,
        name="test_seq",
        dataset="unit",
        source="made by test_bagio",
        frame_id="my_imu",
        meta={"k": "v", "n": str(n)},
    )


def _same(a: Recording, b: Recording) -> None:
    assert np.array_equal(a.stamps_ns, b.stamps_ns)
    assert np.array_equal(a.acc, b.acc)
    assert np.array_equal(a.gyr, b.gyr)
    if a.quat_ref is None:
        assert b.quat_ref is None
    else:
        assert np.array_equal(a.quat_ref, b.quat_ref, equal_nan=True)
    assert np.array_equal(a.score_mask, b.score_mask)
    assert (a.name, a.dataset, a.source, a.frame_id, a.meta) == (b.name, b.dataset, b.source, b.frame_id, b.meta)


@pytest.mark.parametrize(
    ("name", "storage", "compression"),
    [
        ("x.mcap", "mcap", None),
        ("x.mcap", "mcap", "zstd"),
        ("xdir", "mcap", None),
        ("xdb", "sqlite3", None),
        ("xdbz", "sqlite3", "zstd"),
    ],
)
def test_round_trip(tmp_path: Path, name: str, storage: str, compression: str | None) -> None:
    rec = _rec()
    out = bagio.write_recording(tmp_path / name, rec, storage=storage, compression=compression)
    assert out.is_file() == name.endswith(".mcap")
    back = bagio.read_recording(out)
    _same(rec, back)
    assert [p.name for p in tmp_path.iterdir()] == [name]  # no temp left


def test_no_reference_and_all_scored(tmp_path: Path) -> None:
    rec = _rec(with_ref=False)
    rec.score_mask[:] = True
    back = bagio.read_recording(bagio.write_recording(tmp_path / "n.mcap", rec))
    assert back.quat_ref is None
    assert back.score_mask.all()


def test_chunks_equal_whole(tmp_path: Path) -> None:
    rec = _rec(n=1003)
    p = bagio.write_recording(tmp_path / "c.mcap", rec)
    chunks = list(bagio.iter_imu_chunks(p, chunk=100))
    assert [len(c) for c in chunks] == [100] * 10 + [3]
    _same(rec, bagio.concat(chunks))


def test_mcap_reader_sees_topics_and_schemas(tmp_path: Path) -> None:
    from mcap.reader import make_reader

    p = bagio.write_recording(tmp_path / "m.mcap", _rec(n=100), compression="zstd")
    with p.open("rb") as f:
        reader = make_reader(f)
        summary = reader.get_summary()
        assert reader.get_header().profile == "ros2"
        topics = {c.topic: summary.schemas[c.schema_id].name for c in summary.channels.values()}
        counts = {c.topic: summary.statistics.channel_message_counts[c.id] for c in summary.channels.values()}
        assert topics == {
            bagio.IMU_TOPIC: "sensor_msgs/msg/Imu",
            bagio.REF_TOPIC: "geometry_msgs/msg/QuaternionStamped",
            bagio.SCORED_TOPIC: "std_msgs/msg/Bool",
            bagio.INFO_TOPIC: "std_msgs/msg/String",
        }
        assert counts[bagio.IMU_TOPIC] == 100
        assert all(c.message_encoding == "cdr" for c in summary.channels.values())
        # log time = header stamp on the IMU topic
        for _, _channel, msg in reader.iter_messages(topics=[bagio.IMU_TOPIC]):
            stamps, _, _, frame = bagio.parse_imu([msg.data])
            assert stamps[0] == msg.log_time
            assert frame == "my_imu"


def test_imu_message_fields(tmp_path: Path) -> None:
    from rosbags.rosbag2 import Reader

    rec = _rec(n=5)
    p = bagio.write_recording(tmp_path / "f.mcap", rec)
    ts = bagio.typestore()
    with Reader(p) as r:
        conns = [c for c in r.connections if c.topic == bagio.IMU_TOPIC]
        for i, (_, t, raw) in enumerate(r.messages(connections=conns)):
            m = ts.deserialize_cdr(raw, bagio.IMU_TYPE)
            assert m.orientation_covariance[0] == -1.0
            assert m.header.frame_id == "my_imu"
            assert m.header.stamp.sec * 10**9 + m.header.stamp.nanosec == t == rec.stamps_ns[i]
            assert (m.angular_velocity.x, m.angular_velocity.y, m.angular_velocity.z) == tuple(rec.gyr[i])
            assert (m.linear_acceleration.x, m.linear_acceleration.y, m.linear_acceleration.z) == tuple(rec.acc[i])
    info = bagio.read_info(p)
    assert info["format"] == bagio.INFO_FORMAT and info["name"] == "test_seq" and info["samples"] == 5


def test_refuses_existing_and_force(tmp_path: Path) -> None:
    p = bagio.write_recording(tmp_path / "e.mcap", _rec(seed=1))
    with pytest.raises(FileExistsError, match="exists"):
        bagio.write_recording(p, _rec(seed=2))
    rec2 = _rec(seed=2)
    bagio.write_recording(p, rec2, force=True)
    _same(rec2, bagio.read_recording(p))
    # a directory bag can be replaced, an unrelated non-empty folder never
    d = bagio.write_recording(tmp_path / "dirbag", _rec(seed=1), storage="sqlite3")
    bagio.write_recording(d, rec2, storage="sqlite3", force=True)
    _same(rec2, bagio.read_recording(d))
    other = tmp_path / "important"
    other.mkdir()
    (other / "thesis.tex").write_text("x")
    with pytest.raises(FileExistsError, match="not a rosbag2 bag"):
        bagio.write_recording(other, rec2, force=True)
    assert (other / "thesis.tex").exists()


@pytest.mark.parametrize("exc", [RuntimeError, KeyboardInterrupt])
def test_failure_half_way_leaves_nothing(tmp_path: Path, monkeypatch: pytest.MonkeyPatch, exc: type) -> None:
    from rosbags.rosbag2 import Writer

    calls = {"n": 0}
    real = Writer.write

    def flaky(self, conn, t, data):
        calls["n"] += 1
        if calls["n"] == 300:
            raise exc("boom")
        return real(self, conn, t, data)

    monkeypatch.setattr(Writer, "write", flaky)
    for name, storage in (("h.mcap", "mcap"), ("hdir", "sqlite3")):
        calls["n"] = 0
        with pytest.raises(exc):
            bagio.write_recording(tmp_path / name, _rec(), storage=storage)
    assert list(tmp_path.iterdir()) == []


def test_failure_keeps_existing_bag_on_force(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    from rosbags.rosbag2 import Writer

    rec = _rec(seed=5)
    p = bagio.write_recording(tmp_path / "k.mcap", rec)

    def broken(self, conn, t, data):
        raise OSError("disk full")

    monkeypatch.setattr(Writer, "write", broken)
    with pytest.raises(OSError, match="disk full"):
        bagio.write_recording(p, _rec(seed=6), force=True)
    monkeypatch.undo()
    _same(rec, bagio.read_recording(p))
    assert [x.name for x in tmp_path.iterdir()] == ["k.mcap"]


def test_write_recording_rejects_bad_recordings(tmp_path: Path) -> None:
    rec = _rec(n=10)
    rec.stamps_ns[4] = rec.stamps_ns[3]
    with pytest.raises(ValueError, match="sample 4"):
        bagio.write_recording(tmp_path / "b.mcap", rec)
    rec = _rec(n=10)
    rec.gyr[7, 1] = np.nan
    with pytest.raises(ValueError, match="sample 7"):
        bagio.write_recording(tmp_path / "b.mcap", rec)
    with pytest.raises(ValueError, match="storage"):
        bagio.write_recording(tmp_path / "b", _rec(n=10), storage="rosbag1")
    assert list(tmp_path.iterdir()) == []


def test_write_estimates(tmp_path: Path) -> None:
    rec = _rec(n=300)
    src = bagio.write_recording(tmp_path / "src.mcap", rec)
    q = np.tile([1.0, 0.0, 0.0, 0.0], (300, 1))
    q[:, 3] = np.linspace(0, 0.5, 300)
    q /= np.linalg.norm(q, axis=1, keepdims=True)
    q[10] = np.nan
    est = {"/riann/attitude": (rec.stamps_ns, q), "/vqf/attitude": (rec.stamps_ns[::2], q[::2])}
    dst = bagio.write_estimates(src, tmp_path / "dst.mcap", est)
    _same(rec, bagio.read_recording(dst))
    from rosbags.rosbag2 import Reader

    with Reader(dst) as r:
        topics = {c.topic: c.msgtype for c in r.connections}
        assert topics["/riann/attitude"] == bagio.QUAT_TYPE
        conns = [c for c in r.connections if c.topic == "/riann/attitude"]
        raws = [raw for _, _, raw in r.messages(connections=conns)]
        all_t = [t for _, t, _ in r.messages()]
    assert all_t == sorted(all_t)
    st, back = bagio.parse_quats(raws)
    ok = np.isfinite(q).all(axis=1)
    assert np.array_equal(st, rec.stamps_ns[ok]) and np.array_equal(back, q[ok])
    with pytest.raises(FileExistsError):
        bagio.write_estimates(src, dst, est)
    with pytest.raises(FileExistsError, match="input"):
        bagio.write_estimates(src, src, est, force=True)
    bagio.write_estimates(src, dst, {"/x": (rec.stamps_ns, q)}, force=True)
    # to sqlite3 directory from an mcap file
    d = bagio.write_estimates(src, tmp_path / "dstdir", est, storage="sqlite3")
    _same(rec, bagio.read_recording(d))
    assert bagio.bag_compression(d) is None
    # compression follows the source by default
    zsrc = bagio.write_recording(tmp_path / "zsrc.mcap", rec, compression="zstd")
    zdst = bagio.write_estimates(zsrc, tmp_path / "zdst.mcap", est)
    assert bagio.bag_compression(zsrc) == bagio.bag_compression(zdst) == "zstd"
    assert bagio.bag_compression(dst) is None
    zdir = bagio.write_recording(tmp_path / "zdir", rec, storage="sqlite3", compression="zstd")
    zdir2 = bagio.write_estimates(zdir, tmp_path / "zdir2", est)
    assert bagio.bag_compression(zdir2) == "zstd"
    _same(rec, bagio.read_recording(zdir2))


def _two_publisher_bag(path: Path, rec: Recording, identical: bool) -> Path:
    """``rec``'s IMU samples alternately on two connections of one topic, as recorded from two publishers.

    ``identical``: two MCAP channels with the same topic, type and metadata, written with the ``mcap``
    library (rosbags' Writer refuses to add such a second connection, but reads the file as two
    connections); otherwise rosbags' Writer with two connections that differ only in offered QoS.
    """
    rows = [row.tobytes() for row in bagio.imu_messages(rec.stamps_ns, rec.acc, rec.gyr, rec.frame_id)]
    stamps = rec.stamps_ns.tolist()
    ts = bagio.typestore()
    if identical:
        from mcap.writer import Writer as McapWriter

        with path.open("wb") as f:
            w = McapWriter(f)
            w.start(profile="ros2", library="test_bagio")
            msgdef = ts.generate_msgdef(bagio.IMU_TYPE, ros_version=2)[0]
            schema = w.register_schema(name=bagio.IMU_TYPE, encoding="ros2msg", data=msgdef.encode())
            chans = [w.register_channel(bagio.IMU_TOPIC, "cdr", schema) for _ in range(2)]
            for i, (t, raw) in enumerate(zip(stamps, rows, strict=True)):
                w.add_message(chans[i % 2], log_time=t, data=raw, publish_time=t)
            w.finish()
        return path
    from rosbags.interfaces import Qos, QosDurability, QosHistory, QosLiveliness, QosReliability, QosTime
    from rosbags.rosbag2 import StoragePlugin, Writer

    def qos(reliability: QosReliability) -> Qos:
        never = QosTime(0, 0)
        return Qos(QosHistory.KEEP_LAST, 10, reliability, QosDurability.VOLATILE, never, never,
                   QosLiveliness.AUTOMATIC, never, False)  # fmt: skip

    with Writer(path, version=9, storage_plugin=StoragePlugin.MCAP) as w:
        conns = [
            w.add_connection(bagio.IMU_TOPIC, bagio.IMU_TYPE, typestore=ts, offered_qos_profiles=[qos(r)])
            for r in (QosReliability.RELIABLE, QosReliability.BEST_EFFORT)
        ]
        for i, (t, raw) in enumerate(zip(stamps, rows, strict=True)):
            w.write(conns[i % 2], t, raw)
    return path


@pytest.mark.parametrize("identical", [True, False])
def test_write_estimates_two_publishers_on_one_topic(tmp_path: Path, identical: bool) -> None:
    """Several input connections with the same topic and type are copied to one output connection."""
    from rosbags.rosbag2 import Reader

    rec = _rec(n=200, with_ref=False)
    src = _two_publisher_bag(tmp_path / ("src.mcap" if identical else "srcdir"), rec, identical)
    with Reader(src) as r:
        src_qos = [q for c in r.connections for q in c.ext.offered_qos_profiles]
        assert [c.topic for c in r.connections] == [bagio.IMU_TOPIC] * 2
    q = np.tile([1.0, 0.0, 0.0, 0.0], (len(rec), 1))
    est = {"/riann/attitude": (rec.stamps_ns, q)}
    for name, storage in (("dst.mcap", "mcap"), ("dstdir", "sqlite3")):
        dst = bagio.write_estimates(src, tmp_path / name, est, storage=storage)
        with Reader(dst) as r:
            conns = [c for c in r.connections if c.topic == bagio.IMU_TOPIC]
            assert len(conns) == 1 and conns[0].msgcount == len(rec)
            assert len(conns[0].ext.offered_qos_profiles) == len(src_qos)  # both publishers' QoS kept
            assert sum(c.msgcount for c in r.connections if c.topic == "/riann/attitude") == len(rec)
        back = bagio.read_recording(dst)
        assert np.array_equal(back.stamps_ns, rec.stamps_ns)
        assert np.array_equal(back.acc, rec.acc) and np.array_equal(back.gyr, rec.gyr)
        assert back.quat_ref is None and back.frame_id == rec.frame_id


# ---- BagError cases -------------------------------------------------------------------------------


def _foreign_bag(path: Path, topics: dict[str, tuple[str, list[tuple[int, object]]]], storage: str = "mcap") -> Path:
    from rosbags.rosbag2 import StoragePlugin, Writer

    ts = bagio.typestore()
    plugin = StoragePlugin.MCAP if storage == "mcap" else StoragePlugin.SQLITE3
    with Writer(path, version=9, storage_plugin=plugin) as w:
        for topic, (msgtype, msgs) in topics.items():
            c = w.add_connection(topic, msgtype, typestore=ts)
            for t, m in msgs:
                w.write(c, t, bytes(ts.serialize_cdr(m, msgtype)))
    return path


def _string(text: str):
    return bagio.typestore().types["std_msgs/msg/String"](data=text)


def test_bag_errors(tmp_path: Path) -> None:
    with pytest.raises(bagio.BagError, match="no such file"):
        bagio.read_recording(tmp_path / "missing.mcap")
    junk = tmp_path / "junk.mcap"
    junk.write_bytes(b"definitely not an mcap file" * 10)
    with pytest.raises(bagio.BagError, match=r"junk\.mcap"):
        bagio.read_recording(junk)
    txt = tmp_path / "notes.txt"
    txt.write_text("hello")
    with pytest.raises(bagio.BagError, match="not a bag"):
        bagio.read_recording(txt)
    (tmp_path / "emptydir").mkdir()
    with pytest.raises(bagio.BagError, match=r"metadata\.yaml"):
        bagio.read_recording(tmp_path / "emptydir")


def test_truncated_mcap(tmp_path: Path) -> None:
    p = bagio.write_recording(tmp_path / "t.mcap", _rec(n=3000))
    data = p.read_bytes()
    for cut in (len(data) // 2, len(data) - 100, 40):
        bad = tmp_path / f"cut{cut}.mcap"
        bad.write_bytes(data[:cut])
        with pytest.raises(bagio.BagError, match=f"cut{cut}.mcap"):
            bagio.read_recording(bad)


def test_sqlite_missing_table(tmp_path: Path) -> None:
    d = bagio.write_recording(tmp_path / "s", _rec(n=50), storage="sqlite3")
    (db,) = d.glob("*.db3")
    con = sqlite3.connect(db)
    con.execute("DROP TABLE messages")
    con.commit()
    con.close()
    with pytest.raises(bagio.BagError, match=str(d.name)):
        bagio.read_recording(d)


def test_missing_and_wrong_imu_topic(tmp_path: Path) -> None:
    p = _foreign_bag(tmp_path / "noimu", {"/chatter": ("std_msgs/msg/String", [(1, _string("hi"))])})
    with pytest.raises(bagio.BagError, match="no /imu/data_raw topic"):
        bagio.read_recording(p)
    p = _foreign_bag(tmp_path / "wrongtype", {bagio.IMU_TOPIC: ("std_msgs/msg/String", [(1, _string("hi"))])})
    with pytest.raises(bagio.BagError, match="std_msgs/msg/String, expected sensor_msgs/msg/Imu"):
        bagio.read_recording(p)


def test_foreign_bag_generic_path_and_stamp_order(tmp_path: Path) -> None:
    """Messages of varying frame_id go through the generic deserialiser; stamps must increase."""
    ts = bagio.typestore()
    t_ = ts.types
    v3 = t_["geometry_msgs/msg/Vector3"]

    def imu(sec: int, frame: str):
        return t_[bagio.IMU_TYPE](
            header=t_["std_msgs/msg/Header"](
                stamp=t_["builtin_interfaces/msg/Time"](sec=sec, nanosec=5), frame_id=frame
            ),
            orientation=t_["geometry_msgs/msg/Quaternion"](x=0.0, y=0.0, z=0.0, w=1.0),
            orientation_covariance=np.zeros(9),
            angular_velocity=v3(x=0.1 * sec, y=0.0, z=0.0),
            angular_velocity_covariance=np.zeros(9),
            linear_acceleration=v3(x=0.0, y=0.0, z=9.81),
            linear_acceleration_covariance=np.zeros(9),
        )

    msgs = [(s * 10**9 + 5, imu(s, "a" * (s % 3 + 1))) for s in range(1, 6)]
    # an /imu/mag of another type is not this layout's magnetometer: ignored, not an error
    p = _foreign_bag(tmp_path / "foreign", {bagio.IMU_TOPIC: (bagio.IMU_TYPE, msgs),
                                            bagio.MAG_TOPIC: ("std_msgs/msg/String", [(10**9, _string("x"))])})
    rec = bagio.read_recording(p)
    assert rec.quat_ref is None and rec.score_mask.all() and rec.name == "foreign" and rec.mag is None
    assert np.array_equal(rec.stamps_ns, [s * 10**9 + 5 for s in range(1, 6)])
    assert np.allclose(rec.gyr[:, 0], [0.1 * s for s in range(1, 6)])
    # header stamps going back in time (log times increasing) → BagError naming the sample
    msgs = [(k * 10**9, imu(s, "x")) for k, s in enumerate([1, 2, 3, 3, 4], start=1)]
    p = _foreign_bag(tmp_path / "dup", {bagio.IMU_TOPIC: (bagio.IMU_TYPE, msgs)})
    with pytest.raises(bagio.BagError, match="sample 3"):
        bagio.read_recording(p)


def test_synthetic_bag_round_trip(tmp_path: Path) -> None:
    rec = generate(rate=100, duration=20, seed=4)
    _same(rec, bagio.read_recording(bagio.write_recording(tmp_path / "syn.mcap", rec, compression="zstd")))


def test_round_trip_property(tmp_path_factory: pytest.TempPathFactory) -> None:
    """Random lengths, stamps, extreme float64 values, reference gaps and masks round-trip exactly."""
    from hypothesis import given, settings
    from hypothesis import strategies as st

    floats = st.floats(allow_nan=False, allow_infinity=False, width=64)

    @settings(max_examples=10, deadline=None)
    @given(
        n=st.integers(1, 40),
        seed=st.integers(0, 2**32 - 1),
        special=st.lists(floats, min_size=6, max_size=6),
        frame=st.text(min_size=0, max_size=12),
        chunk=st.integers(1, 50),
    )
    def check(n: int, seed: int, special: list[float], frame: str, chunk: int) -> None:
        rng = np.random.default_rng(seed)
        stamps = np.cumsum(rng.integers(1, 10**9, n)) + int(rng.integers(0, 10**18))
        acc = rng.normal(size=(n, 3))
        acc[0] = special[:3]
        gyr = rng.normal(size=(n, 3))
        gyr[-1] = special[3:]
        q = rng.normal(size=(n, 4))
        q[rng.random(n) < 0.3] = np.nan
        rec = Recording(stamps, acc, gyr, q, rng.random(n) < 0.5, name="p", frame_id=frame or "f")
        out = tmp_path_factory.mktemp("prop") / "p.mcap"
        bagio.write_recording(out, rec)
        _same(rec, bagio.concat(list(bagio.iter_imu_chunks(out, chunk=chunk))))

    check()


@pytest.mark.parametrize(("name", "storage"), [("m.mcap", "mcap"), ("mdb", "sqlite3")])
def test_magnetometer_round_trip(tmp_path: Path, name: str, storage: str) -> None:
    """/imu/mag (MagneticField, tesla) is written where the field is finite and read back at the IMU stamps
    (the exact inverse); the evaluator's pairing (NodePairing) pairs it as the nodes do (newest reading at or
    before, within mag_timeout), whole and chunk by chunk; a bag without the topic gives mag None."""
    rec = _rec(600)
    rng = np.random.default_rng(3)
    rec.mag = rng.normal(size=(600, 3)) * 30e-6
    rec.mag[rng.random(600) < 0.2] = np.nan  # a slower magnetometer: no sample at some IMU stamps
    rec.mag[300:450] = np.nan  # and a stretch longer than mag_timeout without one
    path = bagio.write_recording(tmp_path / name, rec, storage=storage)
    back = bagio.read_recording(path)
    _same(rec, back)
    assert np.array_equal(back.mag, rec.mag, equal_nan=True)
    has = np.isfinite(rec.mag).all(axis=1)
    paired = pair_fields(rec.stamps_ns, rec.stamps_ns[has], rec.mag[has], MagConfig().timeout_ns)
    assert np.isfinite(paired[300]).all() and np.isnan(paired[440]).all()  # held, then stale
    assert np.array_equal(bagio.read_recording(path, pair_mag=NodePairing()).mag, paired, equal_nan=True)
    chunks = list(bagio.iter_imu_chunks(path, chunk=97, pair_mag=NodePairing()))
    assert np.array_equal(np.concatenate([c.mag for c in chunks]), paired, equal_nan=True)
    info = bagio.read_info(path)
    assert info["has_mag"] is True and info["topics"]["mag"] == bagio.MAG_TOPIC
    fin = np.flatnonzero(np.isfinite(rec.mag).all(axis=1))[:3]
    rows = bagio.mag_messages(rec.stamps_ns[fin], rec.mag[fin], "f")
    stamps, field = bagio.parse_mags([bytes(r) for r in rows])
    assert np.array_equal(stamps, rec.stamps_ns[fin]) and np.array_equal(field, rec.mag[fin])
    plain = bagio.read_recording(bagio.write_recording(tmp_path / "plain.mcap", _rec(50)))
    assert plain.mag is None and bagio.read_info(tmp_path / "plain.mcap")["has_mag"] is False
