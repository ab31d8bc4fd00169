"""Where recordings come from: sources that yield :class:`Recording` chunks (ROS-free).

A bag at its native rate is read chunk by chunk (memory bounded by the chunk size, not the bag length);
a BROAD trial file, or any recording resampled to another rate (the FFT needs the whole sequence), is
one whole chunk. Everything after the source — scenario, estimators, scoring — is the same code for
both: scoring a whole recording is the one-chunk case.

The first pass over a source (checks, motion onset, rates, rest) is :mod:`~riann_ros.evaluation.first_pass`;
inputs to convert first are named by :mod:`~riann_ros.evaluation.input_hints`.
"""

from __future__ import annotations

import math
import os
from collections.abc import Generator, Iterator
from dataclasses import dataclass, field, replace
from pathlib import Path

import numpy as np
from numpy.typing import NDArray

from riann_ros import defaults
from riann_ros.bagio.layout import IMU_TOPIC, MAG_TOPIC
from riann_ros.constants import NS_PER_S
from riann_ros.evaluation.errors import EvalError
from riann_ros.evaluation.input_hints import BROAD_SUFFIXES, check_input
from riann_ros.evaluation.magpair import NodePairing
from riann_ros.recording import Recording

STREAM_CHUNK = 100_000  # samples per chunk when a bag is read chunk by chunk


ESTIMATE_FILE_OPTIONS = ("--estimate-cols", "--estimate-time-unit")  # for the reader's messages


@dataclass(frozen=True)
class EstimateFile:
    """A trajectory file holding an estimate of one input's sequence (``--estimate-file FILE[:LABEL]``): a TUM file
    (``t tx ty tz qx qy qz qw``, seconds) or a CSV with a header (a time column and qw, qx, qy, qz; read by
    :func:`riann_ros.datasets.euroc.read_ground_truth`), scored like an estimate topic of a bag."""

    path: str
    label: str
    input: str | None = None  # the input whose sequence it estimates (None: every input)
    cols: tuple[str, ...] | None = None  # TIME, QW, QX, QY, QZ column names (None: detect the layout)
    time_unit: str | None = None  # of the time column (None: from its name, else ns; s for TUM files)

    def read(self) -> tuple[NDArray[np.int64], NDArray[np.float64]]:
        """Stamps (ns) and orientations (N, 4) w, x, y, z; EvalError naming the file for anything unreadable."""
        from riann_ros.datasets.euroc import read_ground_truth

        try:
            return read_ground_truth(self.path, self.cols, self.time_unit, options=ESTIMATE_FILE_OPTIONS,
                                     kind="estimate")
        except (OSError, ValueError) as exc:
            raise EvalError(f"estimate file {exc}" if str(exc).startswith(self.path) else
                            f"estimate file {self.path}: {exc}") from exc

    def belongs_to(self, source: Path) -> bool:
        return self.input is None or Path(self.input) == source


@dataclass(frozen=True)
class BagTopics:
    """Which topics of a bag to read: the layout's (:mod:`riann_ros.bagio`) by default, or any bag's
    (:mod:`riann_ros.bagio.topics`): its IMU topic, a ground-truth topic interpolated onto the IMU stamps, and
    estimates recorded from the user's own filters (``estimates``; matched by stamp + ``t_offset_s``); estimates in
    trajectory files (``files``), aligned the same way, for bags and BROAD trials alike."""

    imu: str = IMU_TOPIC
    reference: str | None = None  # None: the layout's /ground_truth/attitude
    mag: str = MAG_TOPIC  # the magnetometer (another topic must be in the bag)
    estimates: tuple[str, ...] = ()
    t_offset_s: float = 0.0  # added to the stamps of the estimate topics and files
    max_gap_s: float = defaults.MAX_GAP_S  # slerp between messages at most this far apart; hold within half of it
    files: tuple[EstimateFile, ...] = ()

    @property
    def plain(self) -> bool:
        """Only the layout's topics (estimate files aside: they are not in the bag)."""
        return self.imu == IMU_TOPIC and self.reference is None and not self.estimates and self.mag == MAG_TOPIC

    def options(self) -> list[str]:
        """The command-line options that ask for these topics (for messages)."""
        out = ([] if self.imu == IMU_TOPIC else ["--imu-topic"]) + ([] if self.mag == MAG_TOPIC else ["--mag-topic"])
        out += ["--ground-truth-topic"] if self.reference else []
        return out + (["--estimate-topic"] if self.estimates else [])


@dataclass
class Chunk(Recording):
    """A piece of a recording with the estimates recorded in the bag at its samples: topic → (N, 4) w, x, y, z
    (NaN rows: no estimate near that sample). Only the recording as it is has them (the as-recorded scenario)."""

    recorded: dict[str, NDArray[np.float64]] = field(default_factory=dict)

    @classmethod
    def of(cls, rec: Recording, recorded: dict[str, NDArray[np.float64]]) -> Chunk:
        return cls(stamps_ns=rec.stamps_ns, acc=rec.acc, gyr=rec.gyr, quat_ref=rec.quat_ref,
                   score_mask=rec.score_mask, name=rec.name, dataset=rec.dataset, source=rec.source,
                   frame_id=rec.frame_id, meta=rec.meta, mag=rec.mag, recorded=recorded)


class Source:
    """A recording as a re-iterable sequence of chunks (each iteration reads it again). The estimates of the
    ``topics.files`` that belong to it are aligned onto every chunk (a :class:`Chunk`)."""

    def __init__(self, path: str | os.PathLike[str], rec: Recording | None = None, chunk: int = STREAM_CHUNK,
                 topics: BagTopics | None = None) -> None:
        self.path = Path(path)
        self.rec = rec  # the whole recording, or None: read the bag chunk by chunk
        self.chunk = chunk
        self.topics = topics or BagTopics()
        self.files = [f for f in self.topics.files if f.belongs_to(self.path)]
        self._file_data: dict[str, tuple[NDArray[np.int64], NDArray[np.float64]]] = {}

    @property
    def resampled(self) -> bool:
        return self.rec is not None and "resampled_from_hz" in self.rec.meta

    def chunks(self) -> Iterator[Recording]:
        if not self.files:
            yield from self._chunks()
            return
        from riann_ros.bagio.topics import Aligner

        t = self.topics
        for f in self.files:
            if f.label not in self._file_data:
                self._file_data[f.label] = f.read()
        aligners = {f.label: Aligner(iter([self._file_data[f.label]]), round(t.t_offset_s * NS_PER_S),
                                     round(t.max_gap_s * NS_PER_S)) for f in self.files}
        for c in self._chunks():
            recorded = dict(c.recorded) if isinstance(c, Chunk) else {}
            recorded.update({label: a.at(c.stamps_ns) for label, a in aligners.items()})
            yield Chunk.of(c, recorded)

    def _chunks(self) -> Iterator[Recording]:
        if self.rec is not None:
            yield self.rec
            return
        it = self._bag_chunks()
        try:
            while True:
                try:
                    c = next(it)
                except StopIteration:
                    return
                except Exception as exc:  # reading only: an estimator crash is reported as such elsewhere
                    raise read_error(self.path, exc) from exc
                yield c
        finally:
            it.close()

    def _bag_chunks(self) -> Generator[Recording, None, None]:
        from riann_ros import bagio

        t = self.topics
        if t.plain:
            yield from bagio.iter_imu_chunks(self.path, chunk=self.chunk, pair_mag=NodePairing())
            return
        from riann_ros.bagio.topics import iter_topic_chunks

        for rec, recorded in iter_topic_chunks(self.path, self.chunk, imu_topic=t.imu, reference_topic=t.reference,
                                               estimate_topics=t.estimates, t_offset_ns=round(t.t_offset_s * NS_PER_S),
                                               max_gap_ns=round(t.max_gap_s * NS_PER_S), pair_mag=NodePairing(),
                                               mag_topic=t.mag):
            yield Chunk.of(rec, recorded) if t.estimates else rec


def _concat(chunks: list[Recording]) -> Recording:
    """The chunks of a source as one recording (a :class:`Chunk` when they carry recorded estimates)."""
    from riann_ros import bagio

    rec = bagio.concat(chunks)
    if chunks and isinstance(chunks[0], Chunk) and chunks[0].recorded:
        topics = list(chunks[0].recorded)
        return Chunk.of(rec, {k: np.concatenate([c.recorded[k] for c in chunks if isinstance(c, Chunk)])
                              for k in topics})
    return rec


def read_error(path: Path, exc: Exception) -> EvalError:
    if isinstance(exc, EvalError):
        return exc
    from riann_ros.bagio.layout import BagError

    if isinstance(exc, BagError) and exc.path == path:
        return EvalError(f"{path}: cannot read: {exc.problem}")
    return EvalError(f"{path}: cannot read: {exc}")


def read_whole(path: str | os.PathLike[str], topics: BagTopics | None = None) -> Recording:
    """A bag (``.mcap``, ``.db3`` or a bag directory; ``topics``: which of its topics) or a BROAD trial file
    (``.hdf5`` / ``.mat``), whole."""
    p = Path(path)
    topics = topics or BagTopics()
    check_input(p)
    if p.suffix.lower() in BROAD_SUFFIXES and not topics.plain:
        raise EvalError(f"{p}: a BROAD trial file, not a bag: {', '.join(topics.options())} apply to bags only")
    try:
        if p.suffix.lower() in BROAD_SUFFIXES:
            from riann_ros.datasets.broad import read_broad

            return read_broad(p)
        if topics.plain:
            from riann_ros import bagio

            return bagio.read_recording(p, pair_mag=NodePairing())
    except Exception as exc:  # bagio.BagError, OSError, ValueError, …
        raise read_error(p, exc) from exc
    # estimate files are aligned by the Source the whole recording goes into (open_source), not here
    return _concat(list(Source(p, topics=replace(topics, files=())).chunks()))


def open_source(path: str | os.PathLike[str], rate: float | None = None, base: Recording | None = None,
                chunk: int = STREAM_CHUNK, topics: BagTopics | None = None) -> Source:
    """The source of ``path`` at ``rate`` Hz (None: its own rate). Bags at their own rate stream chunk by
    chunk; BROAD files and resampled recordings are whole (``base``: the whole recording, if already read)."""
    p = Path(path)
    if rate is None and base is None and p.suffix.lower() not in BROAD_SUFFIXES:
        check_input(p)
        return Source(p, chunk=chunk, topics=topics)
    rec = base if base is not None else read_whole(p, topics)
    if rate is not None:
        from riann_ros.resample import resample_recording

        if not (rate > 0 and math.isfinite(rate)):
            raise ValueError(f"rate must be positive, got {rate}")
        return Source(p, resample_recording(rec, rate))  # estimate files exist for the recording as it is only
    return Source(p, rec, topics=topics)


