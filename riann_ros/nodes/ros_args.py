"""The ``--ros-args`` of a node executable, read before rclpy sees them (ROS-free).

* :func:`normalise` — a list mixing integers and floats (``mag_hard_iron: [0, 0, 1.5e-6]``, or
  ``-p "mag_hard_iron:=[0, 0, 1.5e-6]"``) is refused by rcl's parser ("Sequence should be of same type")
  before any node code runs. Such lists are rewritten as floats: a ``-p`` rule in place, a parameter file
  as a temporary copy. Nothing else in the file changes meaning.
* :func:`foreign_sections` — the sections of the parameter files whose key (a node name, a namespace
  pattern) does not match this node: rcl silently skips them, so a file keyed ``imu_filter:`` (imu_tools'
  node name) would configure nothing without a word.
"""

from __future__ import annotations

import re
import tempfile
from pathlib import Path
from typing import Any

import yaml

PARAMS_FILE = "--params-file"
PARAM_RULE = ("-p", "--param")
ROS_ARGS = "--ros-args"
ROS_ARGS_END = "--"


def _number(v: Any) -> float | None:
    if isinstance(v, bool):
        return None
    if isinstance(v, int | float):
        return float(v)
    if isinstance(v, str):  # PyYAML reads 1e-6 (no dot) as a string; rcl reads it as a double
        try:
            return float(v)
        except ValueError:
            return None
    return None


def uniform(value: Any) -> tuple[Any, bool]:
    """(value with every list of numbers that mixes integers and floats made all floats, whether anything changed)."""
    if isinstance(value, dict):
        out, changed = {}, False
        for k, v in value.items():
            out[k], c = uniform(v)
            changed |= c
        return out, changed
    if isinstance(value, list) and value:
        nums = [_number(v) for v in value]
        is_float = [isinstance(v, float) or (isinstance(v, str) and n is not None) for v, n in zip(value, nums,
                                                                                                   strict=True)]
        if all(n is not None for n in nums) and any(is_float) and not all(is_float):
            return nums, True
    return value, False


def _ros_arg_spans(argv: list[str]) -> list[tuple[int, int]]:
    """[start, end) index ranges of the arguments inside ``--ros-args ... [--]``."""
    spans, i = [], 0
    while i < len(argv):
        if argv[i] == ROS_ARGS:
            j = i + 1
            while j < len(argv) and argv[j] != ROS_ARGS_END:
                j += 1
            spans.append((i + 1, j))
            i = j
        i += 1
    return spans


def params_files(argv: list[str]) -> list[str]:
    """The ``--params-file`` paths of ``argv``, in order."""
    out = []
    for a, b in _ros_arg_spans(argv):
        out += [argv[k + 1] for k in range(a, b - 1) if argv[k] == PARAMS_FILE]
    return out


def normalise(argv: list[str], tmpdir: str | None = None) -> tuple[list[str], list[str]]:
    """(``argv`` with mixed integer/float lists made floats, one note per rewritten rule or file). Files that
    cannot be read are left to rcl (its error is then reported)."""
    out, notes = list(argv), []
    for a, b in _ros_arg_spans(argv):
        for k in range(a, b - 1):
            if argv[k] in PARAM_RULE and ":=" in argv[k + 1]:
                name, text = argv[k + 1].split(":=", 1)
                try:
                    value, changed = uniform(yaml.safe_load(text))
                except yaml.YAMLError:
                    continue
                if changed:
                    out[k + 1] = f"{name}:={yaml.safe_dump(value, default_flow_style=True).strip()}"
                    notes.append(f"{name}: a list mixing integers and floats, read as floats {value}")
            elif argv[k] == PARAMS_FILE:
                fixed = _normalised_file(argv[k + 1], tmpdir)
                if fixed is not None:
                    out[k + 1] = fixed
                    notes.append(f"{argv[k + 1]}: lists mixing integers and floats read as floats")
    return out, notes


def _normalised_file(path: str, tmpdir: str | None) -> str | None:
    try:
        data = yaml.safe_load(Path(path).read_text())
    except (OSError, yaml.YAMLError):
        return None
    data, changed = uniform(data)
    if not changed:
        return None
    with tempfile.NamedTemporaryFile("w", suffix=".yaml", prefix="riann_params_", dir=tmpdir, delete=False) as f:
        yaml.safe_dump(data, f)
        return f.name


def key_matches(key: str, fqn: str) -> bool:
    """Whether a parameter-file section key (``/**``, ``madgwick_node``, ``/robot/*``, ``/**/imu_filter``) applies to
    the node with fully qualified name ``fqn`` (``/robot/madgwick_node``), as rcl matches them."""
    key = key if key.startswith("/") else "/" + key
    parts = []
    for tok in key.strip("/").split("/"):
        if tok == "**":
            parts.append("(/[^/]+)*")
        else:
            parts.append("/" + re.escape(tok).replace(r"\*", "[^/]*"))
    return re.fullmatch("".join(parts) or "/", fqn) is not None


def _sections(data: Any, prefix: str = "") -> list[tuple[str, dict[str, Any]]]:
    """(key, parameters) of every ``ros__parameters`` section, nested namespaces joined with '/'."""
    out: list[tuple[str, dict[str, Any]]] = []
    if not isinstance(data, dict):
        return out
    for key, section in data.items():
        if not isinstance(section, dict):
            continue
        path = f"{prefix}/{key}" if prefix else str(key)
        params = section.get("ros__parameters")
        if isinstance(params, dict):
            out.append((path, params))
        out += _sections({k: v for k, v in section.items() if k != "ros__parameters"}, path)
    return out


def foreign_sections(files: list[str], fqn: str) -> list[tuple[str, str, list[str]]]:
    """(file, key, parameter names) of every section of ``files`` that does not apply to the node ``fqn``."""
    out = []
    for path in files:
        try:
            data = yaml.safe_load(Path(path).read_text())
        except (OSError, yaml.YAMLError):
            continue
        out += [(path, key, sorted(map(str, params))) for key, params in _sections(data)
                if not key_matches(key, fqn)]
    return out
