"""The node's files stay in step with its code: config/riann.yaml, docs/node.md, the Foxglove layout and the
launch files (run against stand-in launch modules: launch_ros is not installable in the .venv).

Regenerate the parameter table of docs/node.md after changing a ParamSpec:
``RIANN_WRITE_DOCS=1 python -m pytest test/test_package_files.py -k docs``.
"""

from __future__ import annotations

import json
import os
import re

import helpers_launch as hl
import pytest

from conftest import ROOT
from riann_ros.estimators import estimator_class
from riann_ros.nodes.madgwick_node import MadgwickNode
from riann_ros.nodes.mahony_node import MahonyNode
from riann_ros.nodes.node_base import INPUT_TOPIC, MAG_TOPIC
from riann_ros.nodes.outputs import rpy_topic
from riann_ros.nodes.parameters import NODE_PARAMS
from riann_ros.nodes.riann_node import RiannNode
from riann_ros.nodes.vqf_node import VqfNode
from riann_ros.params import ParamSpec

DOC = ROOT / "docs" / "node.md"
LAYOUT = ROOT / "config" / "foxglove_side_by_side.json"
NODE_CLASSES = {"riann": RiannNode, "madgwick": MadgwickNode, "mahony": MahonyNode, "vqf": VqfNode}
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
def test_foxglove_layout_plots_roll_and_pitch_of_the_four_nodes():
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


# -- launch files, against stand-in launch modules (test/helpers_launch.py) ----------------------------------
@pytest.fixture
def load_launch(monkeypatch, tmp_path):
    """Load a launch file with stand-ins for launch / launch_ros (which record what they are given)."""
    share = tmp_path / "share" / "riann_ros"
    hl.install_stand_ins(monkeypatch, share)

    def load(file: str):
        mod, entities = hl.load(file)
        return mod, entities, share

    return load


def test_riann_launch_arguments_and_defaults(load_launch):
    mod, entities, share = load_launch("riann.launch.py")
    args = hl.arguments(entities)
    assert args == {
        "params_file": str(share / "config" / "riann.yaml"), "input_topic": "imu/data_raw", "mag_topic": "imu/mag",
        "namespace": "", "attitude_topic": "imu/attitude", "imu_topic": "imu/data", "rpy_topic": "imu/rpy",
        "nominal_rate": "", "world_frame": "", "fixed_frame": "", "publish_tf": "", "publish_rpy": "",
    }
    # the remapped topics are the node's own defaults, the overridable arguments its parameters of that type
    assert set(mod.OUTPUT_TOPICS.values()) == {RiannNode.ATTITUDE_TOPIC, RiannNode.IMU_TOPIC,
                                               rpy_topic(RiannNode.ATTITUDE_TOPIC)}
    assert (mod.INPUT_TOPIC, mod.MAG_TOPIC) == (INPUT_TOPIC, MAG_TOPIC)
    specs = {s.name: s for s in NODE_PARAMS}
    for name, (kind, _) in mod.PARAMETER_ARGUMENTS.items():
        assert type(specs[name].default).__name__ == kind, name
    assert '"riann_node = riann_ros.nodes.riann_node:main"' in (ROOT / "setup.py").read_text()

    # defaults: the parameter file alone, every topic where the node puts it, no namespace
    (node,) = hl.nodes(entities, args)
    assert node.kwargs["executable"] == "riann_node" and node.kwargs["package"] == "riann_ros"
    assert node.kwargs["parameters"] == [str(share / "config" / "riann.yaml")]
    assert node.kwargs["namespace"] is None
    assert dict(node.kwargs["remappings"]) == {"imu/data_raw": "imu/data_raw", "imu/mag": "imu/mag",
                                               "imu/attitude": "imu/attitude", "imu/data": "imu/data",
                                               "imu/rpy": "imu/rpy"}


def test_riann_launch_overrides_only_what_is_given(load_launch):
    _, entities, _ = load_launch("riann.launch.py")
    context = {**hl.arguments(entities), "params_file": "/my.yaml", "input_topic": "/my_imu/data_raw",
               "mag_topic": "/my_imu/mag", "namespace": "robot1", "attitude_topic": "/robot/attitude",
               "nominal_rate": "200", "world_frame": "ned", "publish_tf": "True"}
    (node,) = hl.nodes(entities, context)
    file, overrides = node.kwargs["parameters"]
    assert file == "/my.yaml" and node.kwargs["namespace"] == "robot1"
    assert overrides == {"nominal_rate": 200.0, "world_frame": "ned", "publish_tf": True}
    specs = {s.name: s for s in NODE_PARAMS}
    for name, value in overrides.items():  # values the node accepts
        assert specs[name].validate(value) == value
    remaps = dict(node.kwargs["remappings"])
    assert remaps["imu/data_raw"] == "/my_imu/data_raw" and remaps["imu/attitude"] == "/robot/attitude"
    assert remaps["imu/mag"] == "/my_imu/mag"
    with pytest.raises(ValueError, match="publish_rpy must be true or false"):
        hl.nodes(entities, {**context, "publish_rpy": "yes"})


def test_side_by_side_launch_overrides_only_what_is_given(load_launch):
    mod, entities, share = load_launch("side_by_side.launch.py")
    args = hl.arguments(entities)
    assert args == {"input_topic": "imu/data_raw", "mag_topic": "imu/mag", "namespace": "", "nominal_rate": "",
                    "world_frame": "", "fixed_frame": "", "publish_tf": "", "publish_rpy": ""}
    specs = {s.name: s for s in NODE_PARAMS}
    for name, (kind, _) in mod.PARAMETER_ARGUMENTS.items():
        assert type(specs[name].default).__name__ == kind, name
    # defaults: each node with its own parameter file only (nothing overrides what the files say)
    nodes = {n.kwargs["executable"]: n for n in hl.nodes(entities, args)}
    assert set(nodes) == {f"{n}_node" for n in NODE_CLASSES}
    for exe, node in nodes.items():
        assert node.kwargs["parameters"] == [str(share / "config" / exe.replace("_node", ".yaml"))]
        assert dict(node.kwargs["remappings"]) == {"imu/data_raw": "imu/data_raw", "imu/mag": "imu/mag"}
        assert node.kwargs["namespace"] is None
    # given values go to all four, publish_tf to riann_node only
    context = {**args, "nominal_rate": "200", "publish_tf": "true", "world_frame": "ned", "namespace": "robot1",
               "mag_topic": "/robot1/magnetometer"}
    for node in hl.nodes(entities, context):
        exe = node.kwargs["executable"]
        file, overrides = node.kwargs["parameters"]
        assert file == str(share / "config" / exe.replace("_node", ".yaml"))
        assert overrides == {"nominal_rate": 200.0, "world_frame": "ned",
                             **({"publish_tf": True} if exe == "riann_node" else {})}, exe
        assert node.kwargs["namespace"] == "robot1"
        assert dict(node.kwargs["remappings"])["imu/mag"] == "/robot1/magnetometer"
