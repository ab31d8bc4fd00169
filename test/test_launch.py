"""The launch files (launch/riann.launch.py, launch/side_by_side.launch.py): their arguments and defaults, the nodes
they start with the parameter files and overrides given, run against stand-in launch modules (launch_ros is not
installable in the .venv: test/helpers_launch.py) and, where launch_ros is installed, the real one. Their runs over
DDS: test_launch_smoke.py."""

from __future__ import annotations

import ast
import importlib.util

import helpers_launch as hl
import pytest

from conftest import ROOT
from riann_ros.nodes.node_base import INPUT_TOPIC, MAG_TOPIC
from riann_ros.nodes.outputs import rpy_topic
from riann_ros.nodes.parameters import NODE_PARAMS
from riann_ros.nodes.riann_node import RiannNode

LAUNCH_FILE = ROOT / "launch" / "side_by_side.launch.py"
NODES = ("riann", "madgwick", "mahony", "vqf", "consensus")  # the five node executables, <name>_node


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
    assert set(nodes) == {f"{n}_node" for n in NODES}
    for exe, node in nodes.items():
        assert node.kwargs["parameters"] == [str(share / "config" / exe.replace("_node", ".yaml"))]
        assert dict(node.kwargs["remappings"]) == {"imu/data_raw": "imu/data_raw", "imu/mag": "imu/mag"}
        assert node.kwargs["namespace"] is None
    # given values go to all five, publish_tf to riann_node only
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


def test_launch_file_starts_every_node_executable_with_its_config():
    """Without launch_ros: the launch file's node list = the five console scripts, each with its YAML."""
    tree = ast.parse(LAUNCH_FILE.read_text())
    consts = {t.id: ast.literal_eval(n.value) for n in tree.body if isinstance(n, ast.Assign)
              for t in n.targets if isinstance(t, ast.Name) and t.id in ("NODES", "PACKAGE", "INPUT_TOPIC")}
    assert consts["NODES"] == NODES and consts["PACKAGE"] == "riann_ros"
    assert consts["INPUT_TOPIC"] == "imu/data_raw"
    setup = (ROOT / "setup.py").read_text()
    for name in consts["NODES"]:
        assert f'"{name}_node = riann_ros.nodes.{name}_node:main"' in setup
        assert (ROOT / "config" / f"{name}.yaml").is_file()
    assert 'glob("launch/*.py")' in setup  # installed into share/riann_ros/launch
    # riann.launch.py (its arguments and the node it starts: the stand-in tests above)
    tree = ast.parse((ROOT / "launch" / "riann.launch.py").read_text())
    consts = {t.id: ast.literal_eval(n.value) for n in tree.body if isinstance(n, ast.Assign)
              for t in n.targets if isinstance(t, ast.Name) and t.id in ("NODE", "PACKAGE", "INPUT_TOPIC")}
    assert consts == {"NODE": "riann", "PACKAGE": "riann_ros", "INPUT_TOPIC": "imu/data_raw"}


def test_launch_description_when_launch_ros_is_present(tmp_path, monkeypatch):
    pytest.importorskip("launch_ros")
    from launch.actions import DeclareLaunchArgument, OpaqueFunction

    # a minimal ament prefix so get_package_share_directory("riann_ros") finds config/ without a colcon build
    (tmp_path / "share" / "ament_index" / "resource_index" / "packages").mkdir(parents=True)
    (tmp_path / "share" / "ament_index" / "resource_index" / "packages" / "riann_ros").touch()
    (tmp_path / "share" / "riann_ros").mkdir()
    (tmp_path / "share" / "riann_ros" / "config").symlink_to(ROOT / "config")
    monkeypatch.setenv("AMENT_PREFIX_PATH", str(tmp_path))
    spec = importlib.util.spec_from_file_location("side_by_side_launch", LAUNCH_FILE)
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    ld = mod.generate_launch_description()
    args = [e for e in ld.entities if isinstance(e, DeclareLaunchArgument)]
    assert {a.name for a in args} == {"input_topic", "mag_topic", "namespace", "nominal_rate", "world_frame",
                                      "fixed_frame", "publish_tf", "publish_rpy"}
    assert len([e for e in ld.entities if isinstance(e, OpaqueFunction)]) == 1  # the five nodes


def test_riann_launch_description_when_launch_ros_is_present(tmp_path, monkeypatch):
    pytest.importorskip("launch_ros")
    from launch.actions import DeclareLaunchArgument, OpaqueFunction

    (tmp_path / "share" / "ament_index" / "resource_index" / "packages").mkdir(parents=True)
    (tmp_path / "share" / "ament_index" / "resource_index" / "packages" / "riann_ros").touch()
    (tmp_path / "share" / "riann_ros").mkdir()
    (tmp_path / "share" / "riann_ros" / "config").symlink_to(ROOT / "config")
    monkeypatch.setenv("AMENT_PREFIX_PATH", str(tmp_path))
    spec = importlib.util.spec_from_file_location("riann_launch", ROOT / "launch" / "riann.launch.py")
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    ld = mod.generate_launch_description()
    args = [e for e in ld.entities if isinstance(e, DeclareLaunchArgument)]
    assert {a.name for a in args} == {"params_file", "input_topic", "mag_topic", "namespace", "attitude_topic",
                                      "imu_topic", "rpy_topic", "nominal_rate", "world_frame", "fixed_frame",
                                      "publish_tf", "publish_rpy"}
    assert len([e for e in ld.entities if isinstance(e, OpaqueFunction)]) == 1
