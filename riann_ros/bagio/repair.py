"""Truncated bags: find out how much of a cut-off recording is readable, and write a repaired copy.

A recording stopped by a crash, a full disk or a pulled cable ends in the middle of the file: an MCAP file without
its summary, footer and end magic (``File end magic is invalid``), a sqlite3 file shorter than its header says
(``database disk image is malformed``). Everything written before the cut is usually intact:

* **MCAP**: the records are read in order with the ``mcap`` library's stream reader (chunk CRCs checked) up to the
  first incomplete one; a chunk cut in two is lost whole (a writer's chunks hold about 1 MiB of messages).
  :func:`repair` copies the schema, channel, message, metadata and attachment records read, unchanged, into a new
  MCAP file with a fresh index and summary (zstd chunks if the original's were compressed).
* **sqlite3** (``.db3``): a copy padded to the size its header gives opens; the ``messages`` table is read in ``id``
  order up to the first page past the cut. :func:`repair` writes the topics (types, definitions, QoS, hashes) and
  those messages into a new bag through rosbags.

:func:`truncation` says whether a bag is cut and what can be read; :func:`describe` words it for an error message.
Outputs follow the writers' rules: an existing output is refused unless ``force``, and it is written to a temporary
sibling and renamed at the end (:mod:`~riann_ros.bagio.atomic`).
"""

from __future__ import annotations

import json
import os
import shutil
import sqlite3
import struct
import tempfile
from collections.abc import Iterator
from contextlib import suppress
from dataclasses import dataclass, field
from pathlib import Path

from riann_ros.bagio.atomic import _AtomicBag, _check_target
from riann_ros.bagio.layout import IMU_TOPIC, INFO_TOPIC, STRING_TYPE, BagError, typestore

MCAP_MAGIC = b"\x89MCAP0\r\n"
SQLITE_MAGIC = b"SQLite format 3\x00"


@dataclass
class Truncation:
    """What is readable in a cut-off bag file."""

    path: Path  # the storage file (.mcap or .db3)
    storage: str  # "mcap" or "sqlite3"
    size: int  # bytes in the file
    expected_size: int | None  # bytes the file should have (sqlite3: from its header); None: unknown (MCAP)
    readable_end: int  # bytes up to the end of the last complete record (MCAP) or page (sqlite3)
    messages: dict[str, int] = field(default_factory=dict)  # readable messages per topic
    first_ns: int | None = None  # log times of the readable messages
    last_ns: int | None = None
    samples: int | None = None  # IMU samples of the whole recording, from /dataset/info (riann-bag-convert bags)

    @property
    def total(self) -> int:
        return sum(self.messages.values())


def storage_file(path: Path) -> Path | None:
    """The storage file of a bag: the ``.mcap`` / ``.db3`` file itself, or the only one in a bag directory."""
    if path.is_file():
        return path if path.suffix in (".mcap", ".db3") else None
    if path.is_dir():
        files = sorted([*path.glob("*.mcap"), *path.glob("*.db3")])
        return files[0] if len(files) == 1 else None
    return None


def _cut_mcap(f: Path) -> bool:
    size = f.stat().st_size
    if size < 2 * len(MCAP_MAGIC):
        return True
    with f.open("rb") as fh:
        head = fh.read(len(MCAP_MAGIC))
        fh.seek(-len(MCAP_MAGIC), os.SEEK_END)
        return head == MCAP_MAGIC and fh.read(len(MCAP_MAGIC)) != MCAP_MAGIC


def _sqlite_size(f: Path) -> int | None:
    """The size a sqlite3 file's header gives (page size × pages), None when the header does not say."""
    with f.open("rb") as fh:
        head = fh.read(100)
    if len(head) < 100 or not head.startswith(SQLITE_MAGIC):
        return None
    page = struct.unpack(">H", head[16:18])[0]
    page = 65536 if page == 1 else page
    pages = struct.unpack(">I", head[28:32])[0]
    changes, valid_for = struct.unpack(">I", head[24:28])[0], struct.unpack(">I", head[92:96])[0]
    return page * pages if pages and changes == valid_for else None


def is_truncated(path: str | os.PathLike[str]) -> bool:
    """Whether the bag's storage file is cut off (cheap: the MCAP end magic, the sqlite3 header's size)."""
    f = storage_file(Path(path))
    if f is None or not f.is_file():
        return False
    if f.suffix == ".mcap":
        return _cut_mcap(f)
    expected = _sqlite_size(f)
    return expected is not None and f.stat().st_size < expected


# -- MCAP -----------------------------------------------------------------------------------------------
def _mcap_records(f: Path) -> Iterator[tuple[object, int]]:
    """The complete records of an MCAP file in order (chunks broken up, their CRCs checked), each with the byte
    offset where the readable data ends after it; stops at the first incomplete or damaged record."""
    from mcap.stream_reader import StreamReader

    with f.open("rb") as fh:
        reader = StreamReader(fh, skip_magic=False, validate_crcs=True)
        it = iter(reader.records)
        while True:
            try:
                rec = next(it)
            except StopIteration:
                return
            except Exception:  # the cut (EndOfFile), or damage behind it
                return
            yield rec, fh.tell()


def _info_samples(raw: bytes) -> int | None:
    try:
        info = json.loads(typestore().deserialize_cdr(raw, STRING_TYPE).data)
        return int(info["samples"])
    except Exception:
        return None


def _scan_mcap(f: Path) -> Truncation:
    from mcap.records import Channel, Message

    t = Truncation(f, "mcap", f.stat().st_size, None, 0)
    topics: dict[int, str] = {}
    for rec, end in _mcap_records(f):
        t.readable_end = end
        if isinstance(rec, Channel):
            topics[rec.id] = rec.topic
        elif isinstance(rec, Message):
            topic = topics.get(rec.channel_id, f"channel {rec.channel_id}")
            t.messages[topic] = t.messages.get(topic, 0) + 1
            t.first_ns = rec.log_time if t.first_ns is None else min(t.first_ns, rec.log_time)
            t.last_ns = rec.log_time if t.last_ns is None else max(t.last_ns, rec.log_time)
            if topic == INFO_TOPIC and t.samples is None:
                t.samples = _info_samples(rec.data)
    return t


def _write_mcap(src: Path, tmp: Path) -> None:
    """Copy the readable records of MCAP ``src`` into a complete MCAP file ``tmp``."""
    from mcap.records import Attachment, Channel, Chunk, Header, Message, Metadata, Schema
    from mcap.stream_reader import StreamReader
    from mcap.writer import CompressionType, Writer

    compressed = True
    with src.open("rb") as fh, suppress(Exception):
        compressed = next((r.compression != "" for r in StreamReader(fh, emit_chunks=True).records
                           if isinstance(r, Chunk)), True)
    schemas: dict[int, int] = {}
    channels: dict[int, int] = {}
    with tmp.open("wb") as out:
        w = Writer(out, compression=CompressionType.ZSTD if compressed else CompressionType.NONE)
        started = False
        for rec, _ in _mcap_records(src):
            if isinstance(rec, Header):
                w.start(rec.profile, f"{rec.library} (repaired by riann-bag-convert --repair)")
                started = True
            elif not started:
                raise BagError(src, "no MCAP header record")
            elif isinstance(rec, Schema) and rec.id not in schemas:
                schemas[rec.id] = w.register_schema(rec.name, rec.encoding, rec.data)
            elif isinstance(rec, Channel) and rec.id not in channels:
                channels[rec.id] = w.register_channel(rec.topic, rec.message_encoding,
                                                      schemas.get(rec.schema_id, 0), rec.metadata)
            elif isinstance(rec, Message) and rec.channel_id in channels:
                w.add_message(channels[rec.channel_id], rec.log_time, rec.data, rec.publish_time, rec.sequence)
            elif isinstance(rec, Metadata):
                w.add_metadata(rec.name, rec.metadata)
            elif isinstance(rec, Attachment):
                w.add_attachment(rec.create_time, rec.log_time, rec.name, rec.media_type, rec.data)
        if not started:
            raise BagError(src, "truncated before its MCAP header: nothing to repair")
        w.finish()


# -- sqlite3 --------------------------------------------------------------------------------------------
class _PaddedDb:
    """A read-only connection to a copy of a cut sqlite3 file padded with zeros to the size its header gives (the
    pages past the cut read as empty, so everything before them opens)."""

    def __init__(self, f: Path, expected: int) -> None:
        self.dir = Path(tempfile.mkdtemp(prefix=".riann_repair."))
        self.copy = self.dir / f.name
        shutil.copyfile(f, self.copy)
        with self.copy.open("r+b") as fh:
            fh.truncate(expected)
        self.conn = sqlite3.connect(f"file:{self.copy}?mode=ro", uri=True)

    def close(self) -> None:
        with suppress(Exception):
            self.conn.close()
        shutil.rmtree(self.dir, ignore_errors=True)

    def topics(self) -> list[tuple]:
        """(id, name, type, serialization_format, offered_qos_profiles, type_description_hash)."""
        cols = {r[1] for r in self.conn.execute("PRAGMA table_info(topics)")}
        digest = "type_description_hash" if "type_description_hash" in cols else "''"
        return list(self.conn.execute(f"SELECT id, name, type, serialization_format, offered_qos_profiles, {digest} "
                                      "FROM topics ORDER BY id"))

    def definitions(self) -> dict[str, str]:
        try:
            return {t: d for t, enc, d in self.conn.execute(
                "SELECT topic_type, encoding, encoded_message_definition FROM message_definitions") if enc == "ros2msg"}
        except sqlite3.DatabaseError:
            return {}

    def messages(self, batch: int = 1000) -> Iterator[tuple[int, int, bytes]]:
        """(topic id, timestamp, data) in id order, up to the first unreadable page or row."""
        last = 0
        while True:
            try:
                rows = list(self.conn.execute("SELECT id, topic_id, timestamp, data FROM messages WHERE id > ? "
                                              "ORDER BY id LIMIT ?", (last, batch)))
            except sqlite3.DatabaseError:
                rows = self._one_by_one(last, batch)
                if not rows:
                    return
            if not rows:
                return
            for i, topic_id, stamp, data in rows:
                if topic_id is None or stamp is None or data is None:
                    return  # a row whose record lies past the cut (a zero page reads as empty columns)
                yield topic_id, stamp, data
                last = i

    def _one_by_one(self, last: int, batch: int) -> list[tuple]:
        """The rows after ``last`` that still read one at a time (the batch hit the cut)."""
        rows = []
        for i in range(last + 1, last + batch + 1):
            try:
                row = self.conn.execute("SELECT id, topic_id, timestamp, data FROM messages WHERE id = ?",
                                        (i,)).fetchone()
            except sqlite3.DatabaseError:
                break
            if row is None:
                break
            rows.append(row)
        return rows


def _scan_sqlite(f: Path, expected: int) -> Truncation:
    size = f.stat().st_size
    page = _sqlite_page(f)
    t = Truncation(f, "sqlite3", size, expected, size - size % page)
    db = _PaddedDb(f, expected)
    try:
        names = {row[0]: row[1] for row in db.topics()}
        for topic_id, stamp, data in db.messages():
            topic = names.get(topic_id, f"topic {topic_id}")
            t.messages[topic] = t.messages.get(topic, 0) + 1
            t.first_ns = stamp if t.first_ns is None else min(t.first_ns, stamp)
            t.last_ns = stamp if t.last_ns is None else max(t.last_ns, stamp)
            if topic == INFO_TOPIC and t.samples is None:
                t.samples = _info_samples(bytes(data))
    except sqlite3.DatabaseError:
        pass  # not even the topics table: nothing readable
    finally:
        db.close()
    return t


def _sqlite_page(f: Path) -> int:
    with f.open("rb") as fh:
        head = fh.read(18)
    page = struct.unpack(">H", head[16:18])[0] if len(head) >= 18 else 4096
    return 65536 if page == 1 else page


def _write_sqlite(src: Path, expected: int, dst: Path, storage: str, force: bool) -> None:
    """The readable topics and messages of the cut sqlite3 file ``src`` as a new bag ``dst`` (rosbags Writer)."""
    from rosbags.rosbag2.metadata import parse_qos

    db = _PaddedDb(src, expected)
    try:
        try:
            topics, defs = db.topics(), db.definitions()
        except sqlite3.DatabaseError as exc:
            raise BagError(src, f"truncated before its topics table: nothing to repair ({exc})") from exc
        with _AtomicBag(dst, storage, None, force) as writer:
            conns = {}
            for tid, name, msgtype, fmt, qos, digest in topics:
                known = msgtype in typestore().types
                msgdef = defs.get(msgtype)
                use_store = known and not (msgdef and digest)
                if not use_store and not (msgdef and digest):
                    raise BagError(src, f"topic {name}: type {msgtype} has no definition or hash to copy")
                conns[tid] = writer.add_connection(
                    name, msgtype, typestore=typestore() if use_store else None,
                    msgdef=None if use_store else msgdef, rihs01=None if use_store else digest,
                    serialization_format=fmt, offered_qos_profiles=parse_qos(qos or "[]"))
            for tid, stamp, data in db.messages():
                if tid in conns:
                    writer.write(conns[tid], stamp, bytes(data))
    finally:
        db.close()


# -- public -----------------------------------------------------------------------------------------------
def truncation(path: str | os.PathLike[str]) -> Truncation | None:
    """What is readable in a cut-off bag (reads all of it), or None when the bag is not cut off."""
    f = storage_file(Path(path))
    if f is None or not is_truncated(f):
        return None
    if f.suffix == ".mcap":
        return _scan_mcap(f)
    expected = _sqlite_size(f)
    assert expected is not None
    return _scan_sqlite(f, expected)


def _span(t: Truncation) -> str:
    if t.first_ns is None or t.last_ns is None:
        return ""
    return f", {(t.last_ns - t.first_ns) * 1e-9:.1f} s of log time"


def describe(t: Truncation) -> str:
    """``truncated: …``: where the file ends, what is readable (for messages)."""
    where = (f"the file ends at byte {t.size:,} without the MCAP footer (a recording cut off by a crash or a full "
             "disk); its records are complete up to byte " f"{t.readable_end:,}" if t.storage == "mcap" else
             f"the file has {t.size:,} bytes where its header says {t.expected_size:,} (a recording cut off by a "
             "crash or a full disk)")
    if not t.total:
        return f"truncated: {where}; no message before the cut is readable"
    imu = t.messages.get(IMU_TOPIC)
    of = f" of {t.samples:,}" if imu is not None and t.samples else ""
    parts = ", ".join(f"{n:,} {topic}" for topic, n in sorted(t.messages.items(), key=lambda kv: -kv[1]))
    return (f"truncated: {where}; {t.total:,} messages before the cut are readable ({parts}{_span(t)})"
            + (f": {imu:,}{of} IMU samples" if imu is not None else ""))


def repair_command(path: str | os.PathLike[str]) -> str:
    """The command that writes a repaired copy of ``path``."""
    import shlex

    p = Path(path)
    dst = p.with_name(f"{p.stem if p.is_file() else p.name}_repaired.mcap")
    return f"riann-bag-convert --repair {shlex.quote(str(p))} -o {shlex.quote(str(dst))}"


def repair(src: str | os.PathLike[str], dst: str | os.PathLike[str], *, force: bool = False) -> Truncation:
    """Write the readable part of the cut-off bag ``src`` as a complete bag ``dst``; returns what was readable.
    ``dst``: a ``.mcap`` file (an MCAP input is copied record by record; a sqlite3 input is converted), or, for a
    sqlite3 input, a rosbag2 directory with sqlite3 storage. BagError when ``src`` is not cut off or nothing is
    readable; FileExistsError for an existing ``dst`` without ``force``."""
    src_p, dst_p = Path(src), Path(dst)
    t = truncation(src_p)
    if t is None:
        raise BagError(src_p, "not truncated (its storage file is complete): nothing to repair")
    if not t.total:
        raise BagError(src_p, describe(t))
    if dst_p.resolve() == src_p.resolve() or dst_p.resolve() == t.path.resolve():
        raise FileExistsError(f"{dst_p}: the output is the input; choose another output path")
    if t.storage == "mcap":
        if dst_p.suffix != ".mcap":
            raise ValueError(f"{dst_p}: the repaired copy of an MCAP bag is an MCAP file: give a path ending in .mcap")
        _check_target(dst_p, force)
        dst_p.parent.mkdir(parents=True, exist_ok=True)
        fd, name = tempfile.mkstemp(prefix=f".{dst_p.name}.", suffix=".tmp", dir=dst_p.parent)
        os.close(fd)
        tmp = Path(name)
        try:
            _write_mcap(t.path, tmp)
            _check_target(dst_p, force)
            if dst_p.is_dir() and not dst_p.is_symlink():
                shutil.rmtree(dst_p)
            os.replace(tmp, dst_p)
        finally:
            tmp.unlink(missing_ok=True)
    else:
        assert t.expected_size is not None
        _write_sqlite(t.path, t.expected_size, dst_p, "mcap" if dst_p.suffix == ".mcap" else "sqlite3", force)
    return t
