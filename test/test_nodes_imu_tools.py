"""The ROS-free pieces behind the node's parameter handling (fast; the DDS tests are in test_nodes_parameters.py):
ParamSpec.coerce, imu_tools' names, the --ros-args pre-pass, and the one mapping table of docs/node.md."""

from __future__ import annotations

import math
import re

import pytest
import yaml

from conftest import ROOT
from riann_ros.mag import MAG_PARAMS
from riann_ros.nodes import imu_tools, ros_args
from riann_ros.nodes.parameters import NODE_PARAMS
from riann_ros.params import ParamSpec, find


@pytest.mark.parametrize("spec, value, want", [
    (find(MAG_PARAMS, "use_mag"), False, "false"),
    (find(MAG_PARAMS, "use_mag"), True, "true"),
    (find(MAG_PARAMS, "use_mag"), "Auto", "auto"),
    (find(NODE_PARAMS, "world_frame"), "NED", "ned"),
    (find(NODE_PARAMS, "nominal_rate"), 200, 200.0),
    (find(NODE_PARAMS, "nominal_rate"), "200", 200.0),
    (find(NODE_PARAMS, "input_depth"), 500.0, 500),
    (find(NODE_PARAMS, "publish_rpy"), "true", True),
    (find(NODE_PARAMS, "publish_rpy"), "off", False),
    (find(NODE_PARAMS, "publish_rpy"), 1, True),
    (find(NODE_PARAMS, "fixed_frame"), 7, "7"),
    (find(MAG_PARAMS, "mag_hard_iron"), [0, 0, 1], (0.0, 0.0, 1.0)),
    (find(MAG_PARAMS, "mag_hard_iron"), "0, 0, 1e-6", (0.0, 0.0, 1e-6)),
])
def test_coerce_takes_natural_spellings(spec: ParamSpec, value, want) -> None:
    got = spec.coerce(value)
    assert got == want and type(got) is type(want)


@pytest.mark.parametrize("spec, value, error", [
    (find(MAG_PARAMS, "use_mag"), "sometimes", "use_mag must be one of auto, true, false"),
    (find(NODE_PARAMS, "publish_rpy"), "maybe", "publish_rpy must be a bool"),
    (find(NODE_PARAMS, "publish_rpy"), 2, "publish_rpy must be a bool"),
    (find(NODE_PARAMS, "nominal_rate"), "fast", "nominal_rate must be a number"),
    (find(NODE_PARAMS, "nominal_rate"), 0, "below its minimum"),
    (find(NODE_PARAMS, "input_depth"), 2.5, "input_depth must be an integer"),
    (find(MAG_PARAMS, "mag_hard_iron"), [0, 0], "must be a list of 3 numbers"),
])
def test_coerce_refuses_what_is_not_the_parameter(spec: ParamSpec, value, error: str) -> None:
    with pytest.raises(ValueError, match=error):
        spec.coerce(value)


def test_imu_tools_translations() -> None:
    t = imu_tools.translate("gain", 0.05, "madgwick")
    assert t.values == {"beta": 0.05, "beta_marg": 0.05} and t.refused is None
    assert "no gain to tune" in imu_tools.translate("gain", 0.05, "riann").refused
    assert imu_tools.translate("zeta", 0, "madgwick").refused is None
    assert "no zeta" in imu_tools.translate("zeta", 0.1, "madgwick").refused
    assert imu_tools.translate("mag_bias_y", 3e-6, "vqf").values == {"mag_hard_iron[1]": 3e-6}
    assert imu_tools.translate("declination", 0.1, "riann").values == {"declination_deg": pytest.approx(5.729578)}
    assert imu_tools.translate("yaw_offset", -math.pi / 2, "mahony").values == {"yaw_offset_deg": pytest.approx(-90)}
    t = imu_tools.translate("orientation_stddev", 0.01, "riann")
    d = pytest.approx(0.5729578)
    assert t.values == {"roll_pitch_stddev_deg": d, "mag_yaw_stddev_deg": d, "orientation_covariance": "constant"}
    assert imu_tools.translate("orientation_stddev", 0.0, "riann").values == {}  # imu_tools: covariance unknown
    assert "nominal_rate: 200" in imu_tools.translate("constant_dt", 0.005, "vqf").refused
    assert imu_tools.translate("do_bias_estimation", False, "vqf").values == {"motion_bias_est": False,
                                                                              "rest_bias_est": False}
    assert imu_tools.translate("do_bias_estimation", "true", "mahony").values == {"gyro_bias_estimation": True}
    assert imu_tools.translate("publish_debug_topics", True, "riann").values == {"publish_rpy": True}
    assert "no stateless mode" in imu_tools.translate("stateless", True, "madgwick").refused
    assert "Vector3Stamped" in imu_tools.translate("use_magnetic_field_msg", False, "madgwick").refused
    for name in ("gain_acc", "gain_mag", "bias_alpha", "do_adaptive_gain"):
        assert "imu_complementary_filter" in imu_tools.translate(name, 0.01, "mahony").refused
    assert "input_qos" in imu_tools.translate("qos_overrides./imu/data_raw.subscription.depth", 10, "riann").refused
    assert "must be a number" in imu_tools.translate("gain", "high", "madgwick").refused
    assert imu_tools.translate("beta", 0.1, "madgwick") is None  # ours, not imu_tools'
    names = {s.name for s in NODE_PARAMS}
    assert set(imu_tools.SAME_NAMES) <= names and not set(imu_tools.ALIASES) & names


def test_unknown_text_names_the_owner_or_the_closest_name() -> None:
    known = ["beta", "beta_marg", "gain", "nominal_rate"]
    assert imu_tools.unknown_text("nominal_rte", known, {}) == \
        "unknown parameter 'nominal_rte' ignored (closest known name: 'nominal_rate')"
    assert imu_tools.unknown_text("kp", known, {"kp": ["mahony_node"]}) == \
        "'kp' is a parameter of mahony_node, not of this node: ignored"


def test_ros_args_normalise_mixed_lists(tmp_path) -> None:
    f = tmp_path / "p.yaml"
    f.write_text("/**:\n  ros__parameters:\n    mag_hard_iron: [0, 0, 1.5e-6]\n    ok: [1, 2]\n    s: [a, 1]\n")
    argv = ["riann_node", "--ros-args", "-p", "mag_soft_iron:=[1, 0, 0, 0, 1.0, 0, 0, 0, 1]", "-p", "a:=1",
            "--params-file", str(f), "--", "other", "-p", "x:=[0, 0.5]"]
    out, notes = ros_args.normalise(argv, str(tmp_path))
    assert out[3] == "mag_soft_iron:=[1.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 1.0]" and out[5] == "a:=1"
    assert out[-1] == "x:=[0, 0.5]"  # outside --ros-args: not ours
    fixed = yaml.safe_load(open(out[7]).read())["/**"]["ros__parameters"]
    assert fixed == {"mag_hard_iron": [0.0, 0.0, 1.5e-6], "ok": [1, 2], "s": ["a", 1]}
    assert len(notes) == 2 and ros_args.params_files(argv) == [str(f)]
    assert ros_args.normalise(["x", "--ros-args", "-p", "a:=[1, 2]"])[1] == []


@pytest.mark.parametrize("key, fqn, match", [
    ("/**", "/robot/madgwick_node", True), ("madgwick_node", "/madgwick_node", True),
    ("imu_filter", "/madgwick_node", False), ("imu_filter", "/robot/imu_filter", False),
    ("/robot/*", "/robot/riann_node", True), ("/*", "/robot/riann_node", False),
    ("/**/riann_node", "/a/b/riann_node", True), ("robot/riann_node", "/robot/riann_node", True),
])
def test_parameter_file_keys_match_as_rcl(key: str, fqn: str, match: bool) -> None:
    assert ros_args.key_matches(key, fqn) is match


def test_foreign_sections_of_imu_tools_file() -> None:
    fixture = str(ROOT / "test" / "fixtures" / "imu_filter_madgwick_9d.yaml")
    ((path, key, names),) = ros_args.foreign_sections([fixture], "/madgwick_node")
    assert path == fixture and key == "imu_filter" and "gain" in names and len(names) == 17
    assert ros_args.foreign_sections([fixture], "/imu_filter") == []


def test_docs_have_one_imu_tools_table_with_every_name() -> None:
    doc = (ROOT / "docs" / "node.md").read_text()
    tables = re.findall(r"\n\| imu_tools parameter \|.*?\n\n", doc, re.S)
    assert len(tables) == 1, "one mapping table in docs/node.md"
    first_cells = [line.split("|")[1] for line in tables[0].strip().splitlines()[2:]]
    rows = {name for cell in first_cells for name in re.findall(r"`([\w.*/]+)`", cell)}
    assert rows >= set(imu_tools.ALIASES) | set(imu_tools.SAME_NAMES) | {"qos_overrides.*"}


def test_a_declination_implausible_in_radians_is_warned_about():
    from riann_ros.nodes import imu_tools

    t = imu_tools.translate("declination", 2.5, "riann")
    assert "WARNING" in t.note and "declination_deg" in t.note
    assert "WARNING" not in imu_tools.translate("declination", 0.05, "riann").note
