"""Where recordings come from: sources that yield :class:`Recording` chunks, and their first pass (ROS-free).

A bag at its native rate is read chunk by chunk (memory bounded by the chunk size, not the bag length);
a BROAD trial file, or any recording resampled to another rate (the FFT needs the whole sequence), is
one whole chunk. Everything after the source — scenario, estimators, scoring — is the same code for
both: scoring a whole recording is the one-chunk case.

:func:`summarise` is the first pass over a source: the input checks (samples, reference, scored
samples), the motion onset (first scored sample) and the rates (1 / median stamp step) of the whole
sequence and of the sequence from the motion onset; then, over the samples before the motion onset
only, the rest whose mean gyro is the turn-on bias (:mod:`~riann_ros.evaluation.rest`: detected from the
signals, or given by hand).
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
from riann_ros.bagio.layout import IMU_TOPIC
from riann_ros.constants import NS_PER_S
from riann_ros.evaluation.errors import EvalError
from riann_ros.evaluation.magpair import NodePairing
from riann_ros.evaluation.rest import GIVEN, Rest, RestDetector
from riann_ros.recording import Recording

BROAD_SUFFIXES = (".hdf5", ".h5", ".mat")
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
            return read_ground_truth(self.path, self.cols, self.time_unit, options=ESTIMATE_FILE_OPTIONS)
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
    estimates: tuple[str, ...] = ()
    t_offset_s: float = 0.0  # added to the stamps of the estimate topics and files
    max_gap_s: float = defaults.MAX_GAP_S  # slerp between messages at most this far apart; hold within half of it
    files: tuple[EstimateFile, ...] = ()

    @property
    def plain(self) -> bool:
        """Only the layout's topics (estimate files aside: they are not in the bag)."""
        return self.imu == IMU_TOPIC and self.reference is None and not self.estimates

    def options(self) -> list[str]:
        """The command-line options that ask for these topics (for messages)."""
        out = [] if self.imu == IMU_TOPIC else ["--imu-topic"]
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
                                               max_gap_ns=round(t.max_gap_s * NS_PER_S), pair_mag=NodePairing()):
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


def _q(p: Path) -> str:
    import shlex

    return shlex.quote(str(p))


def _folder_hint(p: Path) -> str | None:
    from riann_ros.datasets.euroc import is_euroc

    if (p / "metadata.yaml").exists():
        return None
    if is_euroc(p):
        bag = p.parent / f"{p.resolve().name}.mcap"
        return (f"{p}: an EuRoC/ASL folder, not a bag; convert it first with riann-bag-convert:\n"
                f"    riann-bag-convert {_q(p)} -o {_q(bag)}\n    riann-bag-eval {_q(bag)}")
    files = sorted(f for f in p.iterdir() if f.suffix.lower() in (*BROAD_SUFFIXES, ".csv"))
    if files:
        out = p.parent / f"{p.resolve().name}_bags"
        return (f"{p}: a folder of dataset files, not a bag; give the BROAD files themselves "
                f"(riann-bag-eval {_q(p)}/*.hdf5 …) or convert them first with riann-bag-convert:\n"
                f"    riann-bag-convert {_q(p)} -o {_q(out)}\n    riann-bag-eval {_q(out)}/*.mcap")
    return None


def input_hint(path: str | os.PathLike[str]) -> str | None:
    """For an input the evaluator does not read but riann-bag-convert does (a CSV file, an EuRoC/ASL folder, a
    folder of dataset files; a ROS 1 bag): what to type instead. None for anything else."""
    p = Path(path)
    if p.is_dir():
        return _folder_hint(p)
    suffix = p.suffix.lower()
    if suffix in (".csv", ".txt") and p.is_file():
        bag = p.with_suffix(".mcap")
        return (f"{p}: a CSV file, not a bag; convert it first with riann-bag-convert (see riann-bag-convert --help "
                f"for the column and unit options, e.g. --time-unit ms --gyr-unit deg/s --quat-cols qw,qx,qy,qz):\n"
                f"    riann-bag-convert {_q(p)} -o {_q(bag)}\n    riann-bag-eval {_q(bag)}")
    if suffix == ".bag" and p.is_file():
        dst = p.with_suffix("")
        return (f"{p}: a ROS 1 bag; convert it to rosbag2 first, then name its topics:\n"
                f"    rosbags-convert --src {_q(p)} --dst {_q(dst)}\n"
                f"    riann-bag-eval {_q(dst)} --imu-topic IMU_TOPIC --ground-truth-topic REFERENCE_TOPIC")
    return None


def check_input(p: Path) -> None:
    """EvalError for a missing input, or one to convert first (:func:`input_hint`)."""
    if not p.exists():
        raise EvalError(f"{p}: no such file or directory")
    hint = input_hint(p)
    if hint:
        raise EvalError(hint)


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


def median_rate(hist: dict[int, int]) -> float:
    """``Recording.rate_hz`` (1 / median step) from a histogram of the stamp steps (ns → count)."""
    n = sum(hist.values())
    if n == 0:
        return float("nan")
    keys = sorted(hist)
    cum = np.cumsum([hist[k] for k in keys])

    def kth(k: int) -> int:  # the k-th smallest step (0-based)
        return keys[int(np.searchsorted(cum, k, side="right"))]

    if n % 2:
        med = float(np.int64(kth(n // 2)) * 1e-9)
    else:
        med = float(np.median(np.array([kth(n // 2 - 1), kth(n // 2)], dtype=np.int64) * 1e-9))
    return 1.0 / med


def _add_steps(hist: dict[int, int], steps: NDArray[np.int64]) -> None:
    if len(steps):
        vals, counts = np.unique(steps, return_counts=True)
        for v, c in zip(vals.tolist(), counts.tolist(), strict=True):
            hist[v] = hist.get(v, 0) + c


@dataclass
class Summary:
    """What the first pass over a source gives before the estimators run (all of bounded size)."""

    name: str
    dataset: str
    citation: str
    frame_id: str
    n: int
    first_stamp: int
    i0: int  # first scored sample (the motion onset); the rest is looked for in [0, i0)
    stamp_i0: int
    rate_all: float  # 1 / median stamp step of the whole sequence
    rate_from_i0: float  # … of the sequence from i0 on
    rest: Rest = field(default_factory=Rest)  # the rest whose mean gyro is the turn-on bias (maybe none)


class _Pass:
    """Running state of :func:`summarise`."""

    def __init__(self) -> None:
        self.n = self.first_stamp = self.stamp_i0 = 0
        self.last: int | None = None
        self.i0 = -1
        self.has_ref = self.ref_any = self.scored_any = self.scored_ref = False
        self.hist_all: dict[int, int] = {}
        self.hist_i0: dict[int, int] = {}
        self.meta: tuple[str, str, str, str] = ("", "", "", "")

    def add(self, c: Recording) -> None:
        m = len(c)
        if self.n == 0:
            self.first_stamp = int(c.stamps_ns[0])
            self.meta = (c.name, c.dataset, c.source, c.frame_id)
            self.has_ref = c.quat_ref is not None
        idx = np.arange(self.n, self.n + m)  # global index of each sample
        if self.last is not None:
            steps, later = np.diff(c.stamps_ns, prepend=np.int64(self.last)), idx
        else:
            steps, later = np.diff(c.stamps_ns), idx[1:]  # later: global index of each step's later sample
        _add_steps(self.hist_all, steps)
        if self.i0 < 0 and c.score_mask.any():
            k = int(np.argmax(c.score_mask))
            self.i0, self.stamp_i0 = self.n + k, int(c.stamps_ns[k])
        if self.i0 >= 0:
            _add_steps(self.hist_i0, steps[later > self.i0])
        self.scored_any |= bool(c.score_mask.any())
        if self.has_ref and c.quat_ref is not None:
            ok = np.isfinite(c.quat_ref).all(axis=1)
            self.ref_any |= bool(ok.any())
            self.scored_ref |= bool((ok & c.score_mask).any())
        self.last = int(c.stamps_ns[-1])
        self.n += m

    def summary(self, p: Path) -> Summary:
        if self.n < 2:
            raise EvalError(f"{p}: fewer than 2 IMU samples")
        if not self.has_ref or not self.ref_any:
            raise EvalError(f"{p}: no reference orientation (nothing to score against)")
        if not self.scored_any:
            raise EvalError(f"{p}: no scored samples (score mask is empty)")
        if not self.scored_ref:
            raise EvalError(f"{p}: no scored samples with a reference")
        name, dataset, citation, frame_id = self.meta
        if not name or name == "sequence":
            name = p.stem if p.is_file() else p.name
        return Summary(
            name=name,
            dataset=dataset or "unknown",
            citation=citation,
            frame_id=frame_id,
            n=self.n,
            first_stamp=self.first_stamp,
            i0=self.i0,
            stamp_i0=self.stamp_i0,
            rate_all=median_rate(self.hist_all),
            rate_from_i0=median_rate(self.hist_i0),
        )


def summarise(src: Source, rest: tuple[float, float] | Rest | None = None) -> Summary:
    """The first pass over ``src``: checks (raising :class:`EvalError` naming the input), motion onset and rates;
    then the rest before the motion onset (a second pass over those samples only). ``rest``: None: detect it; the
    rest given by hand, (start, end) in seconds from the first sample; or the :class:`Rest` of this recording at
    another rate (the resampled recording's rest is the same stretch of time: no rest there, none here)."""
    state = _Pass()
    for c in src.chunks():
        state.add(c)
    summary = state.summary(src.path)
    summary.rest = find_rest(src, summary, rest)
    return summary


def find_rest(src: Source, summary: Summary, given: tuple[float, float] | Rest | None = None) -> Rest:
    """The rest of ``src`` (see :mod:`~riann_ros.evaluation.rest` and :func:`summarise`), reading only as far as
    needed."""
    if isinstance(given, Rest):
        if not given.found or given.start_s is None or given.end_s is None:
            return Rest()
        found = find_rest(src, summary, (given.start_s, given.end_s + 1e-6))  # the span, its last sample included
        found.source = given.source
        return found
    if summary.i0 <= 0 and given is None:
        return Rest()
    det = RestDetector(summary.rate_all, summary.i0, summary.first_stamp, given)
    chunks = src.chunks()
    try:
        for c in chunks:
            det.add(c)
            if det.done:
                break
    finally:
        close = getattr(chunks, "close", None)
        if close is not None:
            close()
    found = det.result()
    if given is not None and found.source != GIVEN:
        length = (det.last_stamp - summary.first_stamp) * 1e-9
        raise EvalError(f"{src.path}: --rest {given[0]:g}:{given[1]:g} holds no samples (the recording lasts "
                        f"{length:.3f} s from its first sample)")
    return found


def load_recording(path: str | os.PathLike[str]) -> Recording:
    """The whole recording of ``path`` after the evaluator's input checks (:func:`summarise`)."""
    rec = read_whole(path)
    s = summarise(Source(path, rec))
    rec.name = s.name
    return rec
