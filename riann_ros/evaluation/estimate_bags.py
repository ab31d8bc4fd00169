"""The estimates of a run written into copies of its input bags (``--write-estimates``, ROS-free): each
estimator's output of the first scenario as a ``geometry_msgs/QuaternionStamped`` topic
``/eval/<scenario>/<estimator>`` beside the input's own topics. Dataset files (BROAD) get no bag copy; their
estimates are in the trajectory files (:mod:`~riann_ros.evaluation.estimate_files`)."""

from __future__ import annotations

import re
from dataclasses import dataclass, field
from pathlib import Path

from riann_ros.evaluation.input_hints import BROAD_SUFFIXES
from riann_ros.evaluation.results import SequenceResult


def topic_for(scenario: str, label: str) -> str:
    """A valid ROS topic name for an estimator's estimates."""
    clean = re.sub(r"[^A-Za-z0-9_]+", "_", label).strip("_")
    return f"/eval/{scenario.replace('-', '_')}/{clean}"


@dataclass
class EstimateBags:
    """What :func:`write_estimate_bags` did: the bags written with their topics, why others were not, and the
    inputs that are no bags (no copy: not a problem)."""

    written: list[tuple[Path, list[str]]] = field(default_factory=list)
    problems: list[str] = field(default_factory=list)
    not_bags: list[Path] = field(default_factory=list)


def write_estimate_bags(results: list[SequenceResult], out_dir: Path, force: bool) -> EstimateBags:
    """A copy of every evaluated input bag in ``out_dir`` with its estimates (``SequenceResult.estimates``, kept with
    ``EvalSettings.keep_estimates``); ``force`` replaces existing copies. Unwritable copies are problems, not
    errors: the other inputs are still written; dataset files are skipped (``not_bags``)."""
    from riann_ros import bagio

    done = EstimateBags()
    out_dir.mkdir(parents=True, exist_ok=True)
    for res in results:
        if res.error or not res.estimates:
            continue
        src = Path(res.source)
        if src.suffix.lower() in BROAD_SUFFIXES:
            done.not_bags.append(src)
            continue
        est = res.estimates
        topics = {topic_for(est["scenario"], lbl): (est["stamps"], q) for lbl, q in est["quats"].items()}
        dst = out_dir / src.name
        try:
            bagio.write_estimates(src, dst, topics, force=force)
            done.written.append((dst, list(topics)))
        except Exception as exc:
            done.problems.append(f"{src}: cannot write estimates to {dst}: {exc}")
    return done
