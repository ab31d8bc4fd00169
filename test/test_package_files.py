"""The package's files stay in step with its code: config/riann.yaml, docs/node.md, the Foxglove layout, and setup.py
and package.xml installing the config and launch files (the launch files themselves: test_launch.py).

Regenerate the parameter table of docs/node.md after changing a ParamSpec:
``RIANN_WRITE_DOCS=1 python -m pytest test/test_package_files.py -k docs``.
"""

from __future__ import annotations

import json
import os
import re

import pytest

from conftest import ROOT
from riann_ros.estimators import estimator_class
from riann_ros.nodes.consensus_node import ConsensusNode
from riann_ros.nodes.madgwick_node import MadgwickNode
from riann_ros.nodes.mahony_node import MahonyNode
from riann_ros.nodes.outputs import rpy_topic
from riann_ros.nodes.parameters import NODE_PARAMS
from riann_ros.nodes.riann_node import RiannNode
from riann_ros.nodes.vqf_node import VqfNode
from riann_ros.params import ParamSpec

DOC = ROOT / "docs" / "node.md"
LAYOUT = ROOT / "config" / "foxglove_side_by_side.json"
NODE_CLASSES = {"riann": RiannNode, "madgwick": MadgwickNode, "mahony": MahonyNode, "vqf": VqfNode,
                "consensus": ConsensusNode}
TABLE_BEGIN = "<!-- node-params:begin (generated from NODE_PARAMS by test/test_package_files.py) -->"
TABLE_END = "<!-- node-params:end -->"


# -- config/riann.yaml -------------------------------------------------------------------------------------
def test_riann_yaml_lists_every_node_and_estimator_parameter_with_its_default():
    yaml = pytest.importorskip("yaml")
    params = yaml.safe_load((ROOT / "config" / "riann.yaml").read_text())["/**"]["ros__parameters"]
    expected = {p.name: list(p.default) if isinstance(p.default, tuple) else p.default
                for p in (*NODE_PARAMS, *estimator_class("riann").PARAMS)}
    assert params == expected
    assert all(type(params[k]) is type(v) for k, v in expected.items())  # 100.0 stays a float in the file


# -- docs/node.md --------------------------------------------------------------------------------------------
def _default(spec: ParamSpec) -> str:
    if isinstance(spec.default, bool):
        return "true" if spec.default else "false"
    if isinstance(spec.default, str):
        return f'"{spec.default}"' if spec.default == "" else spec.default
    return f"{spec.default:g}" if isinstance(spec.default, float) else str(spec.default)


def _range(spec: ParamSpec) -> str:
    if spec.choices:
        return " \\| ".join(spec.choices)
    if spec.min is not None and spec.max is not None:
        return f"{spec.min:g} … {spec.max:g}"
    return ""


def params_table() -> str:
    rows = ["| parameter | default | range | run time | meaning |", "|---|---|---|---|---|"]
    for s in NODE_PARAMS:
        text = s.description.replace("|", "\\|")
        rows.append(f"| `{s.name}` | {_default(s)} | {_range(s)} | {'yes' if s.runtime else 'no'} | {text} |")
    return "\n".join(rows)


def test_docs_parameter_table_is_generated_from_node_params():
    doc = DOC.read_text()
    assert TABLE_BEGIN in doc and TABLE_END in doc
    head, rest = doc.split(TABLE_BEGIN)
    table, tail = rest.split(TABLE_END)
    want = "\n" + params_table() + "\n"
    if os.environ.get("RIANN_WRITE_DOCS") == "1":
        DOC.write_text(head + TABLE_BEGIN + want + TABLE_END + tail)
        table = want
    assert table == want, "docs/node.md parameter table is stale: RIANN_WRITE_DOCS=1 pytest test/test_package_files.py"
    for s in NODE_PARAMS:
        assert f"`{s.name}`" in doc


def test_docs_name_the_topics_diagnostics_and_bad_input_reasons():
    from riann_ros import gate as gt

    doc = DOC.read_text()
    for cls in NODE_CLASSES.values():
        for topic in (cls.ATTITUDE_TOPIC, cls.IMU_TOPIC, rpy_topic(cls.ATTITUDE_TOPIC)):
            assert f"`{topic}`" in doc, topic
    for reason in gt.REJECT_REASONS:
        assert f"`rejected {reason}`" in doc, reason
    for key in ("stamp rate measured (Hz)", "nominal_rate (Hz)", "world frame"):
        assert key in doc
    assert "publish_tf: tf2_msgs not available" in doc


# -- Foxglove layout -----------------------------------------------------------------------------------------
def test_foxglove_layout_plots_roll_and_pitch_of_the_five_nodes():
    layout = json.loads(LAYOUT.read_text())
    assert set(layout) >= {"configById", "layout", "globalVariables", "userNodes", "playbackConfig"}
    panels = layout["configById"]

    def mosaic_ids(node) -> list[str]:
        if isinstance(node, str):
            return [node]
        assert set(node) >= {"first", "second", "direction"} and node["direction"] in ("row", "column")
        return mosaic_ids(node["first"]) + mosaic_ids(node["second"])

    assert sorted(mosaic_ids(layout["layout"])) == sorted(panels)  # every panel placed, none missing
    topics = {"/" + rpy_topic(c.ATTITUDE_TOPIC) for c in NODE_CLASSES.values()}
    fields = {}
    for pid, cfg in panels.items():
        assert pid.startswith("Plot!")
        paths = cfg["paths"]
        for p in paths:
            assert set(p) >= {"value", "enabled", "timestampMethod"}
            assert p["timestampMethod"] in ("receiveTime", "headerStamp") and p["enabled"] is True
        parsed = [re.fullmatch(r"(/[\w/]+)\.vector\.([xyz])", p["value"]) for p in paths]
        assert all(parsed), [p["value"] for p in paths]
        assert {m.group(1) for m in parsed} == topics  # the four nodes' rpy topics, nothing else
        (field,) = {m.group(2) for m in parsed}
        fields[field] = cfg["title"]
    assert set(fields) == {"x", "y"}  # roll (x) and pitch (y)
    assert "Roll" in fields["x"] and "Pitch" in fields["y"]


def test_setup_installs_the_config_and_launch_files():
    setup = (ROOT / "setup.py").read_text()
    assert 'glob("config/*.json")' in setup and 'glob("config/*.yaml")' in setup and 'glob("launch/*.py")' in setup
    pkg = (ROOT / "package.xml").read_text()
    for dep in ("launch", "launch_ros", "tf2_msgs"):
        assert f"<exec_depend>{dep}</exec_depend>" in pkg

