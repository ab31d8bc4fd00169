"""The node's files stay in step with its code: config/riann.yaml, docs/node.md, the Foxglove layout and the
launch files (run against stand-in launch modules: launch_ros is not installable in the .venv).

Regenerate the parameter table of docs/node.md after changing a ParamSpec:
``RIANN_WRITE_DOCS=1 python -m pytest test/test_node_files.py -k docs``.
"""

from __future__ import annotations

import importlib.util
import json
import os
import re
import sys
import types

import pytest

from conftest import ROOT
from riann_ros.estimators import estimator_class
from riann_ros.nodes.madgwick_node import MadgwickNode
from riann_ros.nodes.mahony_node import MahonyNode
from riann_ros.nodes.node_base import NODE_PARAMS, rpy_topic
from riann_ros.nodes.riann_node import RiannNode
from riann_ros.nodes.vqf_node import VqfNode
from riann_ros.params import ParamSpec

DOC = ROOT / "docs" / "node.md"
LAYOUT = ROOT / "config" / "foxglove_side_by_side.json"
NODE_CLASSES = {"riann": RiannNode, "madgwick": MadgwickNode, "mahony": MahonyNode, "vqf": VqfNode}
TABLE_BEGIN = "<!-- node-params:begin (generated from NODE_PARAMS by test/test_node_files.py) -->"
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
    assert table == want, "docs/node.md parameter table is stale: RIANN_WRITE_DOCS=1 pytest test/test_node_files.py"
    for s in NODE_PARAMS:
        assert f"`{s.name}`" in doc


def test_docs_name_the_topics_diagnostics_and_bad_input_reasons():
    from riann_ros import stream as st

    doc = DOC.read_text()
    for cls in NODE_CLASSES.values():
        for topic in (cls.ATTITUDE_TOPIC, cls.IMU_TOPIC, rpy_topic(cls.ATTITUDE_TOPIC)):
            assert f"`{topic}`" in doc, topic
    for reason in st.REJECT_REASONS:
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


# -- launch files, against stand-in launch modules ----------------------------------------------------------
class _Recorder:
    def __init__(self, *args, **kwargs) -> None:
        self.args, self.kwargs = args, kwargs


class LaunchConfiguration(_Recorder):
    def perform(self, context: dict[str, str]) -> str:
        return context[self.args[0]]


class DeclareLaunchArgument(_Recorder):
    @property
    def name(self) -> str:
        return self.args[0]


class OpaqueFunction(_Recorder):
    pass


class Node(_Recorder):
    pass


class ParameterValue(_Recorder):
    pass


class LaunchDescription(_Recorder):
    @property
    def entities(self) -> list:
        return self.args[0]


@pytest.fixture
def load_launch(monkeypatch, tmp_path):
    """Load a launch file with stand-ins for launch / launch_ros (which record what they are given)."""
    mods = {
        "launch": {"LaunchDescription": LaunchDescription},
        "launch.actions": {"DeclareLaunchArgument": DeclareLaunchArgument, "OpaqueFunction": OpaqueFunction},
        "launch.substitutions": {"LaunchConfiguration": LaunchConfiguration},
        "launch_ros": {},
        "launch_ros.actions": {"Node": Node},
        "launch_ros.parameter_descriptions": {"ParameterValue": ParameterValue},
        "ament_index_python.packages": {"get_package_share_directory": lambda pkg: str(tmp_path / "share" / pkg)},
    }
    for name, attrs in mods.items():
        m = types.ModuleType(name)
        for k, v in attrs.items():
            setattr(m, k, v)
        monkeypatch.setitem(sys.modules, name, m)

    def load(file: str):
        spec = importlib.util.spec_from_file_location(file.replace(".", "_"), ROOT / "launch" / file)
        mod = importlib.util.module_from_spec(spec)
        spec.loader.exec_module(mod)
        return mod, mod.generate_launch_description().entities, tmp_path / "share" / "riann_ros"

    return load


def _arguments(entities) -> dict[str, str]:
    return {e.name: e.kwargs["default_value"] for e in entities if isinstance(e, DeclareLaunchArgument)}


def test_riann_launch_arguments_and_defaults(load_launch):
    mod, entities, share = load_launch("riann.launch.py")
    args = _arguments(entities)
    assert args == {
        "params_file": str(share / "config" / "riann.yaml"), "input_topic": "imu/data_raw",
        "attitude_topic": "imu/attitude", "imu_topic": "imu/data", "rpy_topic": "imu/rpy",
        "nominal_rate": "", "world_frame": "", "fixed_frame": "", "publish_tf": "", "publish_rpy": "",
    }
    # the remapped topics are the node's own defaults, the overridable arguments its parameters of that type
    assert set(mod.OUTPUT_TOPICS.values()) == {RiannNode.ATTITUDE_TOPIC, RiannNode.IMU_TOPIC,
                                               rpy_topic(RiannNode.ATTITUDE_TOPIC)}
    specs = {s.name: s for s in NODE_PARAMS}
    for name, (kind, _) in mod.PARAMETER_ARGUMENTS.items():
        assert type(specs[name].default).__name__ == kind, name
    assert '"riann_node = riann_ros.nodes.riann_node:main"' in (ROOT / "setup.py").read_text()

    # defaults: the parameter file alone, every topic where the node puts it
    (fn,) = [e for e in entities if isinstance(e, OpaqueFunction)]
    (node,) = fn.kwargs["function"](args)
    assert node.kwargs["executable"] == "riann_node" and node.kwargs["package"] == "riann_ros"
    assert node.kwargs["parameters"] == [str(share / "config" / "riann.yaml")]
    assert dict(node.kwargs["remappings"]) == {"imu/data_raw": "imu/data_raw", "imu/attitude": "imu/attitude",
                                               "imu/data": "imu/data", "imu/rpy": "imu/rpy"}


def test_riann_launch_overrides_only_what_is_given(load_launch):
    from riann_ros.nodes.node_base import NODE_PARAMS as specs

    _, entities, _ = load_launch("riann.launch.py")
    context = {**_arguments(entities), "params_file": "/my.yaml", "input_topic": "/my_imu/data_raw",
               "attitude_topic": "/robot/attitude", "nominal_rate": "200", "world_frame": "ned",
               "publish_tf": "True"}
    (fn,) = [e for e in entities if isinstance(e, OpaqueFunction)]
    (node,) = fn.kwargs["function"](context)
    file, overrides = node.kwargs["parameters"]
    assert file == "/my.yaml"
    assert overrides == {"nominal_rate": 200.0, "world_frame": "ned", "publish_tf": True}
    for name, value in overrides.items():  # values the node accepts
        assert next(s for s in specs if s.name == name).validate(value) == value
    remaps = dict(node.kwargs["remappings"])
    assert remaps["imu/data_raw"] == "/my_imu/data_raw" and remaps["imu/attitude"] == "/robot/attitude"
    with pytest.raises(ValueError, match="publish_rpy must be true or false"):
        fn.kwargs["function"]({**context, "publish_rpy": "yes"})


def test_side_by_side_launch_passes_the_frame_arguments(load_launch):
    _, entities, share = load_launch("side_by_side.launch.py")
    args = _arguments(entities)
    assert args == {"input_topic": "imu/data_raw", "nominal_rate": "100.0", "world_frame": "enu",
                    "fixed_frame": "odom", "publish_tf": "false", "publish_rpy": "false"}
    specs = {s.name: s for s in NODE_PARAMS}
    for name in ("world_frame", "fixed_frame", "publish_tf", "publish_rpy"):  # launch defaults = node defaults
        assert specs[name].parse(args[name]) == specs[name].default
    nodes = {e.kwargs["executable"]: e for e in entities if isinstance(e, Node)}
    assert set(nodes) == {f"{n}_node" for n in NODE_CLASSES}
    for exe, node in nodes.items():
        file, params = node.kwargs["parameters"]
        assert file == str(share / "config" / exe.replace("_node", ".yaml"))
        want = {"nominal_rate", "world_frame", "fixed_frame", "publish_rpy"} | ({"publish_tf"} if exe == "riann_node"
                                                                                  else set())
        assert set(params) == want, exe
        for name, pv in params.items():
            assert pv.args[0].args[0] == name  # the launch argument of the same name
            assert pv.kwargs["value_type"] is type(specs[name].default)
