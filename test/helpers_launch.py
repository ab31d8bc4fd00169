"""The launch files without launch / launch_ros (not installable from PyPI): stand-in modules that record what
the launch file builds, and the command line launch_ros would run for a recorded ``Node``.

:func:`node_command` follows launch_ros' ``Node`` action (Jazzy): ``--ros-args``, ``-r __node:=<name>``,
``-r __ns:=<namespace>`` when a namespace is given, each parameter file as ``--params-file``, each dict of
parameters written to a temporary YAML file keyed by the node's full name (as launch_ros'
``_create_params_file_from_dict``) and passed the same way, then ``-r from:=to`` per remapping.
"""

from __future__ import annotations

import importlib.util
import sys
import types
from pathlib import Path

import yaml

ROOT = Path(__file__).resolve().parents[1]


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


def install_stand_ins(monkeypatch, share: Path) -> None:
    """Put the stand-in launch modules in ``sys.modules``; the package share directory is ``share``."""
    mods = {
        "launch": {"LaunchDescription": LaunchDescription},
        "launch.actions": {"DeclareLaunchArgument": DeclareLaunchArgument, "OpaqueFunction": OpaqueFunction},
        "launch.substitutions": {"LaunchConfiguration": LaunchConfiguration},
        "launch_ros": {},
        "launch_ros.actions": {"Node": Node},
        "launch_ros.parameter_descriptions": {"ParameterValue": ParameterValue},
        "ament_index_python.packages": {"get_package_share_directory": lambda pkg: str(share)},
    }
    for name, attrs in mods.items():
        m = types.ModuleType(name)
        for k, v in attrs.items():
            setattr(m, k, v)
        monkeypatch.setitem(sys.modules, name, m)


def load(file: str):
    """The launch file module and its LaunchDescription's entities (stand-ins must be installed)."""
    spec = importlib.util.spec_from_file_location(file.replace(".", "_"), ROOT / "launch" / file)
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    return mod, mod.generate_launch_description().entities


def arguments(entities) -> dict[str, str]:
    """{launch argument: default}."""
    return {e.name: e.kwargs["default_value"] for e in entities if isinstance(e, DeclareLaunchArgument)}


def nodes(entities, context: dict[str, str]) -> list[Node]:
    """The Node actions of the launch description for the argument values ``context``."""
    out = [e for e in entities if isinstance(e, Node)]
    for fn in (e for e in entities if isinstance(e, OpaqueFunction)):
        out += fn.kwargs["function"](context)
    return out


def node_command(node: Node, bin_dir: Path, tmp: Path) -> list[str]:
    """The command launch_ros runs for ``node`` (executables from ``bin_dir``)."""
    kw = node.kwargs
    ns = kw.get("namespace")
    full_name = f"{ns.rstrip('/') if ns else ''}/{kw['name']}"
    if not full_name.startswith("/"):
        full_name = "/" + full_name
    cmd = [str(bin_dir / kw["executable"]), "--ros-args", "-r", f"__node:={kw['name']}"]
    if ns:
        cmd += ["-r", f"__ns:={ns if ns.startswith('/') else '/' + ns}"]
    for i, p in enumerate(kw.get("parameters", [])):
        if isinstance(p, dict):
            path = tmp / f"launch_params_{kw['name']}_{i}.yaml"
            path.write_text(yaml.dump({full_name: {"ros__parameters": p}}, default_flow_style=False))
            p = str(path)
        cmd += ["--params-file", str(p)]
    for src, dst in kw.get("remappings", []):
        cmd += ["-r", f"{src}:={dst}"]
    return cmd
