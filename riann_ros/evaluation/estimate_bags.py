"""The estimates of a run in copies of its input bags (``--write-estimates``, ROS-free): each estimator's output of the
first scenario as a ``geometry_msgs/QuaternionStamped`` topic ``/eval/<scenario>/<estimator>`` beside the input's own
topics. Dataset files (BROAD) get no bag copy; their estimates are in the trajectory files. What is written, and
when: :func:`riann_ros.evaluation.estimate_files.write_estimates`."""

from __future__ import annotations

import re
from pathlib import Path
from typing import Any

from riann_ros.evaluation.input_hints import BROAD_SUFFIXES
from riann_ros.evaluation.results import SequenceResult


def topic_for(scenario: str, label: str) -> str:
    """A valid ROS topic name for an estimator's estimates."""
    clean = re.sub(r"[^A-Za-z0-9_]+", "_", label).strip("_")
    return f"/eval/{scenario.replace('-', '_')}/{clean}"


BagCopy = tuple[Path, Path, dict[str, tuple[Any, Any]]]  # input bag, its copy in the folder, topic → estimates


def bag_copies(results: list[SequenceResult], out_dir: Path) -> tuple[list[BagCopy], list[Path]]:
    """The bag copy of every evaluated input bag with estimates (``SequenceResult.estimates``, kept with
    ``EvalSettings.keep_estimates``): (input, copy, topics); and the dataset files, which get none."""
    copies: list[BagCopy] = []
    not_bags: list[Path] = []
    for res in results:
        if res.error or not res.estimates:
            continue
        src = Path(res.source)
        if src.suffix.lower() in BROAD_SUFFIXES:
            not_bags.append(src)
            continue
        est = res.estimates
        topics = {topic_for(est["scenario"], lbl): (est["stamps"], q) for lbl, q in est["quats"].items()}
        copies.append((src, out_dir / src.name, topics))
    return copies, not_bags
