"""imu_tools' parameter names on our nodes (riann_ros.nodes.imu_tools): each translated or refused with a reason,
unknown names answered with their owner or the closest name, the one mapping table of docs/node.md (ROS-free; the
same over DDS: test_nodes_parameters.py)."""

from __future__ import annotations

import math
import re

import pytest

from conftest import ROOT
from riann_ros.nodes import imu_tools
from riann_ros.nodes.parameters import NODE_PARAMS


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
