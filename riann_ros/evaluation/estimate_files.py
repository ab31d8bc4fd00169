"""The estimates of a run as trajectory files the ecosystem reads (``--write-estimates``, ROS-free): per input and
estimator a TUM file (``t x y z qx qy qz qw``, seconds, position 0 0 0: evo's ``tum`` format), and the reference as
one more where the input has one; or CSV files with a header (``time[s],qw,qx,qy,qz``, what ``--estimate-file``
reads back).

Names: ``<sequence>.<scenario>.<label>.tum`` and ``<sequence>.<scenario>.reference.tum``, each part made safe for
file names (runs of characters other than letters, digits, ``_``, ``-`` and ``+`` become ``_``:
``madgwick(beta=0.1)`` → ``madgwick_beta_0_1``). The estimates are those of the first scenario (as for the bag
copies, :mod:`~riann_ros.evaluation.estimate_bags`) at the IMU stamps, without the samples the input gate rejected.
The reference file holds the reference at the samples that are scored (score mask, reference present), so that
``evo_ape`` pairing it with an estimate by stamp counts the samples riann-bag-eval's scores count.
"""

from __future__ import annotations

import re
from collections.abc import Sequence
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
from numpy.typing import NDArray

from riann_ros.evaluation.results import REFERENCE, SequenceResult

FORMATS = ("tum", "csv")
CSV_HEADER = "time[s],qw,qx,qy,qz"


def safe(text: str) -> str:
    """``text`` as a file-name part: runs of other characters than letters, digits, ``_``, ``-``, ``+`` → ``_``."""
    return re.sub(r"[^A-Za-z0-9_+-]+", "_", text).strip("_") or "_"


def parse_formats(text: str) -> tuple[str, ...]:
    """``"tum"``, ``"csv"`` or ``"tum,csv"`` → the formats; ValueError otherwise."""
    out = tuple(dict.fromkeys(t.strip().lower() for t in text.split(",") if t.strip()))
    bad = [t for t in out if t not in FORMATS]
    if bad or not out:
        raise ValueError(f"--write-format {text!r}: give tum, csv or tum,csv")
    return out


def file_stem(sequence: str, scenario: str, label: str) -> str:
    return ".".join(safe(p) for p in (sequence, scenario, label))


def _time_texts(stamps_ns: NDArray[np.int64]) -> list[str]:
    """Stamps as exact decimal seconds (9 digits after the point)."""
    sec, ns = np.divmod(stamps_ns.astype(np.int64), 1_000_000_000)
    return [f"{s}.{n:09d}" for s, n in zip(sec.tolist(), ns.tolist(), strict=True)]


def write_trajectory(path: Path, stamps_ns: NDArray[np.int64], quats: NDArray[np.float64], fmt: str) -> int:
    """One trajectory file (rows with a non-finite quaternion left out); the rows written."""
    ok = np.isfinite(quats).all(axis=1)
    times = _time_texts(stamps_ns[ok])
    q = quats[ok] + 0.0  # no "-0.000000000"
    tmp = path.with_name(path.name + ".part")
    with tmp.open("w") as f:
        if fmt == "tum":
            # no "," ";" or tab in the comment: a CSV reader (ours, --estimate-file) would take it for a header
            f.write("# t x y z qx qy qz qw  riann-bag-eval --write-estimates  position not estimated: 0 0 0\n")
            f.writelines(f"{t} 0 0 0 {x:.9f} {y:.9f} {z:.9f} {w:.9f}\n" for t, (w, x, y, z) in zip(times, q.tolist(),
                                                                                                 strict=True))
        else:
            f.write(CSV_HEADER + "\n")
            f.writelines(f"{t},{w:.9f},{x:.9f},{y:.9f},{z:.9f}\n" for t, (w, x, y, z) in zip(times, q.tolist(),
                                                                                          strict=True))
    tmp.replace(path)
    return int(ok.sum())


def _trajectories(res: SequenceResult) -> dict[str, tuple[NDArray[np.int64], NDArray[np.float64]]]:
    """Label → (stamps, quaternions) of an input's kept estimates, the reference (scored samples only) last."""
    est = res.estimates or {}
    stamps = est.get("stamps", np.zeros(0, np.int64))
    out = {label: (stamps, q) for label, q in est.get("quats", {}).items()}
    ref = est.get("reference")
    if ref is not None:
        keep = np.asarray(est["scored"], dtype=bool) & np.isfinite(ref).all(axis=1)
        out[REFERENCE] = (stamps[keep], ref[keep])
    return out


@dataclass(frozen=True)
class Trajectory:
    """One trajectory file to write: where, what, in which format, and the input it comes from."""

    path: Path
    stamps: NDArray[np.int64]
    quats: NDArray[np.float64]
    fmt: str
    source: str


def trajectories(results: Sequence[SequenceResult], out_dir: Path,
                 formats: Sequence[str] = ("tum",)) -> tuple[list[Trajectory], list[str]]:
    """The trajectory files of every evaluated input, and the labels whose file names clash (two labels that give
    one file name: neither can be written under it)."""
    out: list[Trajectory] = []
    problems: list[str] = []
    for res in results:
        if res.error or not res.estimates:
            continue
        scenario = res.estimates["scenario"]
        stems: dict[str, str] = {}
        for label, (stamps, quats) in _trajectories(res).items():
            stem = file_stem(res.name, scenario, label)
            if stem in stems:
                problems.append(f"{res.source}: the labels {stems[stem]!r} and {label!r} give the same file name "
                                f"{stem}")
                continue
            stems[stem] = label
            out += [Trajectory(out_dir / f"{stem}.{fmt}", stamps, quats, fmt, res.source) for fmt in formats]
    return out, problems


@dataclass
class Written:
    """What :func:`write_estimates` did: the bag copies (with their topics) and trajectory files written, the
    dataset inputs that get no bag copy, and the problems (each naming its file)."""

    bags: list[tuple[Path, list[str]]] = field(default_factory=list)
    files: list[Path] = field(default_factory=list)
    not_bags: list[Path] = field(default_factory=list)
    problems: list[str] = field(default_factory=list)


def clashes(targets: Sequence[Path], inputs: Sequence[str], force: bool) -> list[str]:
    """Why files cannot be written at ``targets``: one that exists (unless ``force``), two that are one file, one that
    is an input (never replaced, whatever ``force``)."""
    out = []
    own = {Path(i).resolve() for i in inputs}
    seen: set[Path] = set()
    for t in targets:
        r = t.resolve()
        if r in own:
            out.append(f"{t} is an input: it would be replaced by its own copy (choose another folder)")
        elif r in seen:
            out.append(f"{t}: two inputs of the same file name would be written there")
        elif (t.exists() or t.is_symlink()) and not force:
            out.append(f"{t} exists: not overwriting it (--force replaces it)")
        seen.add(r)
    return out


def write_estimates(results: Sequence[SequenceResult], out_dir: Path, formats: Sequence[str] = ("tum",),
                    force: bool = False) -> Written:
    """``--write-estimates`` into ``out_dir``: every bag copy (:func:`~riann_ros.evaluation.estimate_bags.bag_copies`)
    and trajectory file (:func:`trajectories`) is planned first; any clash (:func:`clashes`, two labels of one file
    name) and nothing is written. Otherwise all are written; one that fails is a problem naming it, the others are
    still written."""
    from riann_ros.evaluation.estimate_bags import bag_copies

    copies, not_bags = bag_copies(list(results), out_dir)
    files, problems = trajectories(results, out_dir, formats)
    done = Written(not_bags=not_bags)
    problems += clashes([dst for _, dst, _ in copies] + [t.path for t in files], [r.source for r in results], force)
    if problems:
        done.problems = [*problems, f"nothing written in {out_dir}"]
        return done
    try:
        out_dir.mkdir(parents=True, exist_ok=True)
    except OSError as exc:
        done.problems = [f"cannot create {out_dir}: {exc.strerror or exc}; nothing written there"]
        return done
    done.bags, bag_problems = _write_bags(copies, force)
    done.problems += bag_problems
    for t in files:
        try:
            write_trajectory(t.path, t.stamps, t.quats, t.fmt)
            done.files.append(t.path)
        except OSError as exc:
            done.problems.append(f"{t.source}: cannot write {t.path}: {exc.strerror or exc}")
    return done


def _write_bags(copies: Sequence[tuple[Path, Path, dict]], force: bool) -> tuple[list[tuple[Path, list[str]]],
                                                                                 list[str]]:
    from riann_ros import bagio

    written, problems = [], []
    for src, dst, topics in copies:
        try:
            bagio.write_estimates(src, dst, topics, force=force)
            written.append((dst, list(topics)))
        except Exception as exc:  # a bag that cannot be copied must not stop the others
            problems.append(f"{src}: cannot write estimates to {dst}: {exc}")
    return written, problems
