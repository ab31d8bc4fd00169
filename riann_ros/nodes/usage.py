"""``<node> --help``: usage, ROS arguments, topics and every parameter of a node executable (ROS-free).

:func:`help_requested` looks for ``-h``/``--help`` outside ``--ros-args … [--]`` (where rcl's own arguments are);
:func:`usage` writes the text from the parameter specs the node declares (:data:`riann_ros.nodes.parameters`'s
``NODE_PARAMS`` and the estimator's ``PARAMS``), so the help and the node never disagree. The node base prints it and
exits before rclpy is initialised: no DDS participant, no node.
"""

from __future__ import annotations

import textwrap
from collections.abc import Sequence

from riann_ros.params import ParamSpec

HELP_FLAGS = ("-h", "--help")
WIDTH = 100


def help_requested(argv: Sequence[str]) -> bool:
    """Whether ``argv`` (program name first) asks for help outside its ``--ros-args`` spans."""
    inside = False
    for a in argv[1:]:
        if a == "--ros-args":
            inside = True
        elif a == "--" and inside:
            inside = False
        elif a in HELP_FLAGS and not inside:
            return True
    return False


def _default(spec: ParamSpec) -> str:
    d = spec.default
    if isinstance(d, bool):
        return "true" if d else "false"
    if isinstance(d, str):
        return f'"{d}"' if d == "" else d
    if isinstance(d, tuple):
        return "[" + ", ".join(f"{v:g}" for v in d) + "]"
    return f"{d:g}" if isinstance(d, float) else str(d)


def _range(spec: ParamSpec) -> str:
    if spec.choices:
        return " | ".join(spec.choices)
    if spec.min is not None and spec.max is not None:
        return f"{spec.min:g} … {spec.max:g}"
    return ""


def _param_lines(specs: Sequence[ParamSpec]) -> list[str]:
    lines = []
    for s in specs:
        extra = "; ".join(x for x in (_range(s), "run time" if s.runtime else "") if x)
        lines.append(f"  {s.name} = {_default(s)}" + (f"  [{extra}]" if extra else ""))
        lines += textwrap.wrap(s.description, WIDTH, initial_indent="      ", subsequent_indent="      ",
                               break_on_hyphens=False)
    return lines


def usage(node: str, summary: str, topics: Sequence[tuple[str, str, str]], node_params: Sequence[ParamSpec],
          estimator: str, estimator_params: Sequence[ParamSpec]) -> str:
    """The help text of ``node``: ``topics`` as (direction, name, type and note), then the node's and the estimator's
    parameters with default, range, whether they may change at run time, and description."""
    lines = [
        f"usage: {node} [-h] [--ros-args [-r FROM:=TO] [-p NAME:=VALUE] [--params-file FILE] [--log-level LEVEL] "
        "[--]]",
        "",
        *textwrap.wrap(summary, WIDTH, break_on_hyphens=False),
        "",
        "options:",
        "  -h, --help            show this help and exit (ROS is not started)",
        "",
        "ROS arguments (after --ros-args, each may repeat; end them with --):",
        "  -r FROM:=TO           remap a topic (-r imu/data_raw:=/my_imu/data_raw), the node's name (-r __node:=NAME)",
        "                        or its namespace (-r __ns:=/robot1)",
        "  -p NAME:=VALUE        set a parameter (-p nominal_rate:=200)",
        "  --params-file FILE    parameters from a YAML file (config/<node>.yaml, keyed '/**' or the node's name)",
        "  --log-level LEVEL     debug, info, warn, error or fatal",
        "",
        "topics (relative names follow the node's namespace):",
        *(f"  {d:4} {name:24} {what}" for d, name, what in topics),
        "",
        "parameters (name = default [range; run time: may be set while running]):",
        *_param_lines(node_params),
        "",
        f"{estimator} parameters:",
        *_param_lines(estimator_params),
        "",
        "Reference: docs/node.md (and docs/riann.md, docs/filters.md for the estimators' parameters).",
    ]
    return "\n".join(lines) + "\n"
