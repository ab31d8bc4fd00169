"""Reading bags: opening a reader, the ``/dataset/info`` record, IMU recordings in bounded chunks, and the
storage and compression of an existing bag."""

from __future__ import annotations

import json
import os
from collections.abc import Callable, Iterator
from contextlib import contextmanager, suppress
from pathlib import Path

import numpy as np

from riann_ros import defaults
from riann_ros.bagio.cdr import parse_imu, parse_mags, parse_quats
from riann_ros.bagio.layout import (
    BOOL_TYPE,
    IMU_TOPIC,
    IMU_TYPE,
    INFO_TOPIC,
    MAG_TOPIC,
    MAG_TYPE,
    QUAT_TYPE,
    REF_TOPIC,
    SCORED_TOPIC,
    STRING_TYPE,
    BagError,
    typestore,
)
from riann_ros.recording import Recording

# (chunk's IMU stamps (N,), magnetometer stamps (M,) sorted, fields (M, 3)) -> (N, 3) field per sample, NaN rows
# where none. Called once per chunk, in order, with the readings stamped at or before the chunk's last sample that
# earlier calls did not get; a stateful pairer may carry readings across chunks.
MagPairer = Callable[[np.ndarray, np.ndarray, np.ndarray], np.ndarray]


def exact_stamps(stamps: np.ndarray, mag_stamps: np.ndarray, mag: np.ndarray) -> np.ndarray:
    """The default :data:`MagPairer`: a reading stamped exactly like the sample, NaN rows elsewhere (the inverse
    of :func:`~riann_ros.bagio.write.write_recording`, which writes the field at the samples' stamps). How an
    estimator pairs a magnetometer with the samples is the caller's policy (the evaluator's:
    :mod:`riann_ros.evaluation.magpair`)."""
    out = np.full((len(stamps), 3), np.nan)
    pos = np.searchsorted(stamps, mag_stamps)
    ok = (pos < len(stamps)) & (stamps[np.minimum(pos, len(stamps) - 1)] == mag_stamps)
    out[pos[ok]] = mag[ok]
    return out


def _open_reader(path: Path):
    """An open rosbags Reader, or BagError."""
    from rosbags.rosbag2 import Reader

    if not path.exists():
        raise BagError(path, "no such file or directory")
    if path.is_dir() and not (path / "metadata.yaml").exists():
        raise BagError(path, "not a rosbag2 bag (directory without metadata.yaml)")
    if path.is_file() and path.suffix not in (".mcap", ".db3"):
        raise BagError(path, "not a bag (expected a rosbag2 directory, a .mcap or a .db3 file)")
    try:
        reader = Reader(path)
        reader.open()
    except BagError:
        raise
    except Exception as e:
        raise _truncated_error(path) or BagError(path, f"cannot open bag ({type(e).__name__}: {e})") from e
    return reader


def _truncated_error(path: Path) -> BagError | None:
    """For a bag that does not open because its recording was cut off: what is readable and how to use it."""
    from riann_ros.bagio import repair

    try:
        t = repair.truncation(path)
    except Exception:
        return None
    if t is None:
        return None
    if not t.total:
        return BagError(path, repair.describe(t))
    return BagError(path, f"{repair.describe(t)}. Score the readable part with riann-bag-eval --salvage, or write a "
                    f"repaired copy: {repair.repair_command(path)}")


@contextmanager
def _opened(path: Path):
    """``with _opened(path) as reader``: :func:`_open_reader`, closed (errors ignored) on leaving."""
    reader = _open_reader(path)
    try:
        yield reader
    finally:
        with suppress(Exception):
            reader.close()


def bag_storage(path: Path) -> str:
    """``"sqlite3"`` for a ``.db3`` file or a directory bag with ``.db3`` storage, else ``"mcap"``."""
    if path.is_file():
        return "sqlite3" if path.suffix == ".db3" else "mcap"
    return "sqlite3" if any(path.glob("*.db3*")) else "mcap"


def bag_compression(path: Path) -> str | None:
    """``"zstd"`` when the bag uses any compression (MCAP chunks, rosbag2 message/file mode), else None."""
    try:
        if path.is_dir():
            import yaml

            meta = yaml.safe_load((path / "metadata.yaml").read_text())["rosbag2_bagfile_information"]
            if meta.get("compression_mode"):
                return "zstd"
            files = sorted(path.glob("*.mcap"))
            if not files:
                return None
            path = files[0]
        if path.suffix != ".mcap":
            return None
        from mcap.reader import make_reader

        with path.open("rb") as f:
            summary = make_reader(f).get_summary()
        chunks = summary.chunk_indexes if summary is not None else []
        return "zstd" if any(c.compression for c in chunks) else None
    except Exception:
        return None


def _topic_connections(path: Path, reader, topic: str, msgtype: str, required: bool) -> list:
    conns = [c for c in reader.connections if c.topic == topic]
    if not conns:
        if required:
            have = ", ".join(sorted({c.topic for c in reader.connections})) or "none"
            raise BagError(path, f"no {topic} topic (topics: {have})")
        return []
    wrong = sorted({c.msgtype for c in conns if c.msgtype != msgtype})
    if wrong:
        raise BagError(path, f"topic {topic} has type {', '.join(wrong)}, expected {msgtype}")
    return conns


def read_info(path: str | os.PathLike[str]) -> dict:
    """The ``/dataset/info`` JSON of a bag ({} when absent or unparsable)."""
    path = Path(path)
    with _opened(path) as reader:
        return _info_from(path, reader)


def _info_from(path: Path, reader) -> dict:
    conns = _topic_connections(path, reader, INFO_TOPIC, STRING_TYPE, required=False)
    if not conns:
        return {}
    try:
        for _, _, raw in reader.messages(connections=conns):
            text = typestore().deserialize_cdr(raw, STRING_TYPE).data
            info = json.loads(text)
            return info if isinstance(info, dict) else {}
    except (ValueError, TypeError):
        return {}
    return {}


def iter_imu_chunks(path: str | os.PathLike[str], chunk: int = 100_000, *, imu_topic: str = IMU_TOPIC,
                    reference: bool = True, pair_mag: MagPairer | None = None,
                    mag_topic: str = MAG_TOPIC) -> Iterator[Recording]:
    """Yield the bag as consecutive :class:`Recording` chunks of at most ``chunk`` samples, in stamp order.

    Memory stays bounded by the chunk size. Each chunk carries its reference (NaN rows where no
    ``/ground_truth/attitude`` message has the sample's stamp; ``quat_ref=None`` when the bag has no
    reference topic, or with ``reference=False``), its score mask and the bag's name/dataset/source/frame_id/meta.
    ``imu_topic``: the ``sensor_msgs/msg/Imu`` topic of the samples (a bag not written by the converter). The
    magnetometer (``/imu/mag``, tesla) comes in ``mag``, paired with the samples by ``pair_mag`` (default
    :func:`exact_stamps`: the reading with the sample's stamp, NaN rows where none), ``None`` without the topic;
    ``mag_topic``: another ``sensor_msgs/msg/MagneticField`` topic, which must then be in the bag.
    Raises :class:`BagError` for anything that is not a readable IMU bag.
    """
    path = Path(path)
    if chunk < 1:
        raise ValueError("chunk must be >= 1")
    with _opened(path) as reader:
        try:
            yield from _iter_chunks(path, reader, chunk, imu_topic, reference, pair_mag or exact_stamps, mag_topic)
        except BagError:
            raise
        except (KeyboardInterrupt, GeneratorExit):
            raise
        except Exception as e:
            raise BagError(path, f"unreadable or truncated bag ({type(e).__name__}: {e})") from e


class _ChunkBuffer:
    """The messages :func:`_iter_chunks` has read but not yet yielded, and what carries from one chunk to the next.

    IMU messages (raw CDR and log time), reference messages (raw CDR) and score-mask events (log time,
    value) are buffered as they arrive in log-time order; :meth:`flush` turns the first ``n`` IMU
    messages into a :class:`Recording` with their reference rows and score mask.
    """

    def __init__(self, path: Path, info: dict, has_ref: bool, imu_ids: set, ref_ids: set,
                 imu_topic: str = IMU_TOPIC, mag_ids: set | None = None, pair_mag: MagPairer = exact_stamps) -> None:
        self.path = path
        self.imu_topic = imu_topic
        self.info = info
        self.has_ref = has_ref
        self.imu_ids = imu_ids
        self.ref_ids = ref_ids
        self.mag_ids = mag_ids or set()
        self.pair_mag = pair_mag
        self.bool_deser = typestore().deserialize_cdr
        self.imu_raw: list[bytes] = []
        self.imu_log: list[int] = []
        self.ref_raw: list[bytes] = []
        self.mag_raw: list[bytes] = []
        self.events: list[tuple[int, bool]] = []
        self.mask = True  # score mask value in force
        self.last: int | None = None  # stamp of the last sample
        self.index = 0  # global index of the next sample
        self.frame: str | None = None

    def add(self, conn_id: int, t: int, raw: bytes) -> None:
        """Buffer one message (log time ``t``) of an IMU, reference or score-mask connection."""
        if conn_id in self.imu_ids:
            self.imu_raw.append(raw)
            self.imu_log.append(t)
        elif conn_id in self.ref_ids:
            self.ref_raw.append(raw)
        elif conn_id in self.mag_ids:
            self.mag_raw.append(raw)
        else:
            self.events.append((t, bool(self.bool_deser(raw, BOOL_TYPE).data)))

    def complete(self, chunk: int, t: int) -> bool:
        """A full chunk is buffered and a message at log time ``t`` is past its last IMU message."""
        return len(self.imu_raw) >= chunk and t > self.imu_log[chunk - 1]

    def drain(self, chunk: int) -> Iterator[Recording]:
        """The remaining chunks once all messages are read; BagError when there was no IMU message at all."""
        while len(self.imu_raw) > chunk:
            yield self.flush(chunk)
        if self.imu_raw:
            yield self.flush(len(self.imu_raw))
        elif self.index == 0:
            raise BagError(self.path, f"topic {self.imu_topic} has no messages")

    def flush(self, n: int) -> Recording:
        """The first ``n`` buffered IMU messages as a :class:`Recording`, removed from the buffer."""
        raws = self.imu_raw[:n]
        del self.imu_raw[:n]
        del self.imu_log[:n]
        stamps, acc, gyr, frame = parse_imu(raws)
        if self.frame is None:
            self.frame = frame
        first = self.index
        self._check_increasing(stamps, first)
        last = int(stamps[-1])
        quat = _at_stamps(self.ref_raw, parse_quats, 4, stamps, last) if self.has_ref else None
        mag = self._paired_mag(stamps, last) if self.mag_ids else None
        mask = self._score_mask(stamps, last)
        self.last = last
        self.index = first + len(stamps)
        return self._recording(stamps, acc, gyr, quat, mask, mag)

    def _paired_mag(self, stamps: np.ndarray, last: int) -> np.ndarray:
        """The field paired with each of the chunk's samples by ``pair_mag``, given the readings stamped at or
        before ``last`` (in stamp order); keeps the readings stamped after ``last`` for later chunks."""
        ts, vals = parse_mags(self.mag_raw)
        vals = vals.reshape(-1, 3)
        now = ts <= last
        order = np.argsort(ts[now], kind="stable")
        out = self.pair_mag(stamps, ts[now][order], vals[now][order])
        self.mag_raw[:] = [r for r, keep in zip(self.mag_raw, ~now, strict=True) if keep]
        return out

    def _check_increasing(self, stamps: np.ndarray, first: int) -> None:
        """BagError naming the global sample index where header stamps stop increasing (across chunks too)."""
        prev = np.concatenate([[self.last], stamps]) if self.last is not None else stamps
        bad = np.flatnonzero(np.diff(prev) <= 0)
        if len(bad):
            i = first + int(bad[0]) + (0 if self.last is not None else 1)
            raise BagError(self.path, f"{self.imu_topic} header stamps not strictly increasing at sample {i}")

    def _score_mask(self, stamps: np.ndarray, last: int) -> np.ndarray:
        """Score mask from on-change events with log time <= stamp; keeps the events logged after ``last``."""
        mask = np.empty(len(stamps), dtype=bool)
        ev = sorted(e for e in self.events if e[0] <= last)
        later = [e for e in self.events if e[0] > last]
        et = np.array([e[0] for e in ev], dtype=np.int64)
        ev_vals = np.array([self.mask] + [e[1] for e in ev], dtype=bool)
        mask[:] = ev_vals[np.searchsorted(et, stamps, side="right")]
        if ev:
            self.mask = ev[-1][1]
        self.events[:] = later
        return mask

    def _recording(
        self, stamps: np.ndarray, acc: np.ndarray, gyr: np.ndarray, quat: np.ndarray | None, mask: np.ndarray,
        mag: np.ndarray | None = None,
    ) -> Recording:
        info = self.info
        return Recording(
            stamps_ns=stamps,
            acc=acc,
            gyr=gyr,
            quat_ref=quat,
            score_mask=mask,
            name=str(info.get("name") or self.path.stem),
            dataset=str(info.get("dataset") or ""),
            source=str(info.get("source") or ""),
            frame_id=str(info.get("frame_id") or self.frame or defaults.IMU_FRAME),
            meta={str(k): str(v) for k, v in (info.get("meta") or {}).items()},
            mag=mag,
        )


def _at_stamps(raws: list[bytes], parse, width: int, stamps: np.ndarray, last: int) -> np.ndarray:
    """Rows of stamped messages (reference, magnetometer) at the chunk's IMU stamps, NaN where none has the
    stamp; keeps in ``raws`` the messages stamped after ``last`` (they belong to later chunks)."""
    out = np.full((len(stamps), width), np.nan)
    ts, vals = parse(raws)
    pos = np.searchsorted(stamps, ts)
    ok = (pos < len(stamps)) & (stamps[np.minimum(pos, len(stamps) - 1)] == ts)
    out[pos[ok]] = vals[ok]
    raws[:] = [r for r, t in zip(raws, ts, strict=True) if t > last]
    return out


def _iter_chunks(path: Path, reader, chunk: int, imu_topic: str = IMU_TOPIC,
                 reference: bool = True, pair_mag: MagPairer = exact_stamps,
                 mag_topic: str = MAG_TOPIC) -> Iterator[Recording]:
    c_imu = _topic_connections(path, reader, imu_topic, IMU_TYPE, required=True)
    c_ref = _topic_connections(path, reader, REF_TOPIC, QUAT_TYPE, required=False) if reference else []
    c_scored = _topic_connections(path, reader, SCORED_TOPIC, BOOL_TYPE, required=False)
    # the layout's magnetometer is optional: a /imu/mag of another type (a foreign bag) is ignored, not an error; a
    # topic asked for by name must be there
    c_mag = ([c for c in reader.connections if c.topic == MAG_TOPIC and c.msgtype == MAG_TYPE]
             if mag_topic == MAG_TOPIC else _topic_connections(path, reader, mag_topic, MAG_TYPE, required=True))
    info = _info_from(path, reader)
    buf = _ChunkBuffer(path, info, bool(c_ref), {c.id for c in c_imu}, {c.id for c in c_ref}, imu_topic,
                       {c.id for c in c_mag}, pair_mag)
    for conn, t, raw in reader.messages(connections=[*c_imu, *c_ref, *c_scored, *c_mag]):
        if buf.complete(chunk, t):
            yield buf.flush(chunk)
        buf.add(conn.id, t, raw)
    yield from buf.drain(chunk)


def concat(chunks: list[Recording]) -> Recording:
    """Concatenate recordings of the same sequence (metadata from the first)."""
    if not chunks:
        raise ValueError("nothing to concatenate")
    if len(chunks) == 1:
        return chunks[0]
    first = chunks[0]
    has_ref = first.quat_ref is not None
    has_mag = first.mag is not None
    return Recording(
        stamps_ns=np.concatenate([c.stamps_ns for c in chunks]),
        acc=np.concatenate([c.acc for c in chunks]),
        gyr=np.concatenate([c.gyr for c in chunks]),
        quat_ref=np.concatenate([c.quat_ref for c in chunks]) if has_ref else None,
        score_mask=np.concatenate([c.score_mask for c in chunks]),
        name=first.name,
        dataset=first.dataset,
        source=first.source,
        frame_id=first.frame_id,
        meta=dict(first.meta),
        mag=np.concatenate([c.mag for c in chunks if c.mag is not None]) if has_mag else None,
    )


def read_recording(path: str | os.PathLike[str], pair_mag: MagPairer | None = None) -> Recording:
    """Read a whole bag (the exact inverse of :func:`write_recording`; ``pair_mag`` as in
    :func:`iter_imu_chunks`)."""
    # chunks keep the raw-bytes buffer small
    return concat(list(iter_imu_chunks(path, chunk=100_000, pair_mag=pair_mag)))
