"""The --ros-args pre-pass (riann_ros.nodes.ros_args): mixed number lists made uniform for rcl, parameter-file keys
matched the way rcl matches them, the sections of a parameter file written for another node (ROS-free)."""

from __future__ import annotations

import pytest
import yaml

from conftest import ROOT
from riann_ros.nodes import ros_args


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
