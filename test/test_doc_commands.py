"""Every shell command in the code blocks of README.md, docs/*.md and bags/README.md runs as pasted from the repository
root after the README's set-up (`make setup`: the tools in .venv/bin).

The commands are taken from the fenced ``bash``/``sh`` blocks and expanded by bash itself (comments, line
continuations, variables, globs such as ``bags/*.mcap``, braces) in a copy of the repository's layout where every
executable only records its arguments. Each command is then checked by the first rule that applies:

* ``.venv/bin/riann-bag-eval``, ``.venv/bin/riann-bag-convert``, ``.venv/bin/riann-topic``,
  ``.venv/bin/riann-mag-calibrate``: the executable exists and
  the command line parses with the command's own parser; every file it reads exists in the repository (``bags/``),
  in BROAD (``../shared/datasets/broad``), is made by an earlier command of the same page, or is named ``my_…``
  (your own file, as the README says);
* ``.venv/bin/<node>``: ``--help``, or its ``--ros-args`` against the node's parameters (each ``-p`` value converts,
  each ``--params-file`` exists);
* ``.venv/bin/<another package's tool>`` (installed from requirements*.txt): it exists;
* ``ros2 run riann_ros <node> …`` and ``ros2 launch riann_ros <file> …`` (a ROS 2 workspace): the node and its
  ``--ros-args`` as above, or the launch file and its declared arguments; ``colcon build`` and
  ``source install/setup.bash`` are the workspace's own steps (test_colcon_smoke.py builds and runs them);
* ``make <target>``: the Makefile has the target (``make demo`` runs in test_demo_smoke.py, ``make test`` is this
  suite);
* anything else (a bare ``riann-bag-eval`` without ``.venv/bin/``) fails.

:func:`test_cheap_doc_commands_run` (slow) then runs for real, page by page in a scratch copy of the repository's
layout, every command that is cheap and has its inputs: ``riann-bag-eval`` and ``riann-bag-convert`` on the bundled
synthetic bags, on BROAD single trials, on what earlier commands made, and the nodes' ``--help``. Checked by parsing
only, with the reason in :func:`run_or_why_not`: ``--live`` (a real-time replay over DDS), ``--tune`` and ``--rates``
(long), ``--scheduler tcp://…`` (a cluster of your own), the real trial in ``bags/`` and all BROAD trials at once
(long; make demo runs the former), BROAD files on a machine without them (a clone: bags/README.md says where to get
BROAD), what rewrites the bundled bags in ``bags/`` (bags/make_bags.sh), files named
``my_…``, and what needs running nodes (``riann-topic``, node command lines, ``ros2``).
"""

from __future__ import annotations

import os
import re
import shlex
import subprocess
from dataclasses import dataclass
from pathlib import Path

import pytest
import yaml

from conftest import ROOT

DOCS = [ROOT / "README.md", *sorted((ROOT / "docs").glob("*.md")), ROOT / "bags" / "README.md"]
SHELL_LANGS = {"bash", "sh", "shell"}
SCRIPTS = dict(re.findall(r'"([\w-]+) = (riann_ros\.[\w.]+):main"', (ROOT / "setup.py").read_text()))
NODES = {name for name, module in SCRIPTS.items() if module.startswith("riann_ros.nodes.")}
BROAD = "../shared/datasets/broad"
SHARE = "install/riann_ros/share/riann_ros/"  # the package share of a colcon workspace: config/, launch/ here
REAL_TRIAL = "bags/broad_21_undisturbed_fast_combined.mcap"
_SEP, _END = "\x1f", "\x1e"


@dataclass
class Command:
    doc: str  # path relative to the repository
    line: int  # where the command starts
    argv: list[str]

    def __str__(self) -> str:
        return f"{self.doc}:{self.line}: {shlex.join(self.argv)}"


def shell_blocks(path: Path) -> list[tuple[int, list[str]]]:
    """(line of the first command line, lines) of each fenced bash/sh block."""
    out, block, start, lang = [], None, 0, ""
    for n, line in enumerate(path.read_text().splitlines(), 1):
        m = re.match(r"^\s*```(\w*)\s*$", line)
        if m and block is None:
            block, start, lang = [], n + 1, m.group(1)
        elif m:
            if lang in SHELL_LANGS:
                out.append((start, block))
            block = None
        elif block is not None:
            block.append(line)
    return out


def _script(blocks: list[tuple[int, list[str]]], log: Path) -> str:
    """A bash script that runs the blocks with every command recording its expanded arguments instead."""
    lines = [f"export LOG={shlex.quote(str(log))}", "export PATH=/nonexistent",
             f"__rec() {{ printf '%s{_SEP}' \"$@\" >> \"$LOG\"; printf '{_END}' >> \"$LOG\"; }}",
             "command_not_found_handle() { __rec \"$@\"; }", "source() { __rec source \"$@\"; }"]
    for start, block in blocks:
        k = 0
        while k < len(block):
            first = k
            while block[k].rstrip().endswith("\\") and k + 1 < len(block):
                k += 1
            group = block[first : k + 1]
            group[-1] = re.sub(r"\s&\s*(#.*)?$", "", group[-1])  # a background job: recorded in order instead
            lines += [f"__rec __LINE__ {start + first}", *group]
            k += 1
    return "\n".join(lines) + "\n"


def _layout(where: Path) -> Path:
    """A copy of the repository's layout at ``where/repo``: bags/ and .venv (links), ../shared (BROAD, when there)."""
    repo = where / "repo"
    repo.mkdir(parents=True)
    (repo / "bags").symlink_to(ROOT / "bags")
    shared = ROOT.parent / "shared"
    if shared.exists():
        (where / "shared").symlink_to(shared)
    return repo


def _folder(doc: str) -> str:
    """A scratch folder's name for a page (README.md and bags/README.md apart)."""
    return doc.removesuffix(".md").replace("/", "_")


def commands(tmp: Path) -> list[Command]:
    """Every command of every page, in page order, as bash expands it from the repository root."""
    out = []
    for doc in DOCS:
        blocks = shell_blocks(doc)
        if not blocks:
            continue
        where = tmp / _folder(str(doc.relative_to(ROOT)))
        repo = _layout(where)
        shims = repo / ".venv" / "bin"
        shims.mkdir(parents=True)
        for exe in (ROOT / ".venv" / "bin").iterdir():
            (shims / exe.name).write_text("#!/bin/sh\nprintf '%s\\037' \"$0\" \"$@\" >> \"$LOG\"\n"
                                          "printf '\\036' >> \"$LOG\"\n")
            (shims / exe.name).chmod(0o755)
        log = where / "log"
        log.write_text("")
        r = subprocess.run(["/bin/bash", "-c", _script(blocks, log)], cwd=repo, capture_output=True, text=True,
                           timeout=60)
        assert r.returncode == 0, f"{doc.name}: bash could not run its blocks: {r.stderr}"
        line = 0
        for rec in log.read_text().split(_END)[:-1]:
            argv = rec.split(_SEP)[:-1]
            if argv[:1] == ["__LINE__"]:
                line = int(argv[1])
            else:
                out.append(Command(str(doc.relative_to(ROOT)), line, argv))
    return out


# -- what a command reads and writes ---------------------------------------------------------------------------


def _parse(cmd: Command, tool: str):
    """The namespace of ``tool``'s own parser for ``cmd`` (a parse error fails with the command)."""
    import importlib

    module = {"riann-bag-eval": "riann_ros.cli.evaluate_parser", "riann-bag-convert": "riann_ros.cli.convert_parser",
              "riann-topic": "riann_ros.cli.topic", "riann-mag-calibrate": "riann_ros.cli.magcal_parser"}[tool]
    parser = importlib.import_module(module).build_parser()
    try:
        return parser.parse_args(cmd.argv[1:])
    except SystemExit as e:
        if e.code:
            pytest.fail(f"{cmd}: {tool} refuses its arguments (exit status {e.code})")
        return None  # --help


def _file_of(spec: str) -> str:
    """The file of an ``--estimate-file FILE[:LABEL]``."""
    head, sep, label = spec.rpartition(":")
    return head if sep and "/" not in label and "." not in label else spec


def files(cmd: Command, ns) -> tuple[list[str], list[str]]:
    """(files and folders the command reads, those it writes)."""
    tool = Path(cmd.argv[0]).name
    if ns is None:
        return [], []
    if tool == "riann-bag-eval":
        reads = [*map(str, ns.inputs), *(_file_of(s) for s in ns.estimate_file), *map(str, ns.compare or []),
                 *ns.inputs_from]
        writes = [str(p) for p in (ns.out, ns.write_estimates) if p is not None]
    elif tool == "riann-bag-convert":
        reads = [*map(str, ns.inputs), *([str(ns.ground_truth)] if ns.ground_truth else [])]
        writes = [str(ns.output)] if ns.output else []
    elif tool == "riann-mag-calibrate":
        reads = [str(ns.bag), *([str(ns.prior)] if ns.prior else [])]
        writes = [str(p) for p in (ns.out, ns.plots) if p is not None]
    else:
        reads, writes = [], []
    return [r.rstrip("/") for r in reads], [w.rstrip("/") for w in writes]


def _yours(path: str) -> bool:
    return any(part.startswith("my_") for part in Path(path).parts)


def _made(path: str, made: set[str]) -> bool:
    return any(path == m or path.startswith(m + "/") for m in made)


def check_reads(cmd: Command, reads: list[str], made: set[str]) -> None:
    for path in reads:
        if _yours(path) or _made(path, made) or path.startswith(BROAD) or (ROOT / path).exists():
            continue
        pytest.fail(f"{cmd}: {path} does not exist: use a bundled file (bags/…), a file an earlier command of the page "
                    "makes, or call it my_… (your own file, README 'Quick start')")


# -- nodes, ros2, make ---------------------------------------------------------------------------------------


def check_ros_args(cmd: Command, node: str, args: list[str]) -> str:
    """The node's command line: ``--help``, or ``--ros-args`` whose parameters the node declares."""
    from riann_ros.estimators import estimator_class
    from riann_ros.nodes.parameters import NODE_PARAMS
    from riann_ros.nodes.usage import help_requested

    if help_requested([node, *args]):
        return "help"
    specs = {s.name: s for s in (*NODE_PARAMS, *estimator_class(node.removesuffix("_node")).PARAMS)}
    assert args[:1] == ["--ros-args"], f"{cmd}: expected --ros-args"
    i = 1
    while i < len(args) and args[i] != "--":
        flag, value = args[i], args[i + 1]
        if flag in ("-p", "--param"):
            name, _, text = value.partition(":=")
            assert name in specs, f"{cmd}: {node} has no parameter {name!r}"
            specs[name].coerce(yaml.safe_load(text))
        elif flag == "--params-file":
            path = ROOT / value.removeprefix(SHARE)
            assert path.is_file(), f"{cmd}: no parameter file {value}"
            for params in yaml.safe_load(path.read_text()).values():
                assert set(params["ros__parameters"]) <= set(specs), f"{cmd}: {value} has parameters {node} lacks"
        elif flag in ("-r", "--remap"):
            assert re.fullmatch(r"[\w/~]+:=[\w/~]+", value), f"{cmd}: remap {value!r}"
        else:
            assert flag == "--log-level", f"{cmd}: unknown ROS argument {flag}"
        i += 2
    return "ros-args"


def check_launch(cmd: Command, file: str, args: list[str], monkeypatch) -> None:
    from helpers_launch import arguments, install_stand_ins, load

    assert (ROOT / "launch" / file).is_file(), f"{cmd}: no launch file {file}"
    install_stand_ins(monkeypatch, ROOT)
    declared = arguments(load(file)[1])
    for a in args:
        name = a.partition(":=")[0]
        assert ":=" in a and name in declared, f"{cmd}: {file} declares no argument {name!r}"


def check(cmd: Command, made: set[str], monkeypatch) -> tuple[str, list[str], list[str]]:
    """Check one command; (how it is checked, files it reads, files it writes)."""
    exe, args = cmd.argv[0], cmd.argv[1:]
    if exe.startswith(".venv/bin/"):
        tool = exe.removeprefix(".venv/bin/")
        assert (ROOT / exe).is_file(), f"{cmd}: {exe} is not installed by make setup"
        if tool not in SCRIPTS:
            return "installed tool", [], []  # another package's (requirements*.txt): it exists
        if tool in NODES:
            return "node " + check_ros_args(cmd, tool, args), [], []
        ns = _parse(cmd, tool)
        reads, writes = files(cmd, ns)
        check_reads(cmd, reads, made)
        return "parsed", reads, writes
    if exe == "make":
        targets = set(re.findall(r"^([\w-]+):", (ROOT / "Makefile").read_text(), re.M))
        assert set(args) <= targets, f"{cmd}: the Makefile has no target {set(args) - targets}"
        return "make target", [], []
    if exe == "ros2" and args[:2] == ["run", "riann_ros"]:
        assert args[2] in NODES, f"{cmd}: riann_ros has no node {args[2]}"
        return "workspace " + check_ros_args(cmd, args[2], args[3:]), [], []
    if exe == "ros2" and args[:2] == ["launch", "riann_ros"]:
        check_launch(cmd, args[2], args[3:], monkeypatch)
        return "workspace launch", [], []
    if cmd.argv in (["colcon", "build"], ["source", "install/setup.bash"]):
        return "workspace step", [], []
    hint = f" (write .venv/bin/{exe})" if exe in SCRIPTS or (ROOT / ".venv" / "bin" / exe).is_file() else ""
    pytest.fail(f"{cmd}: not a command of this repository's set-up{hint}")


def checked(tmp: Path, monkeypatch) -> list[tuple[Command, str, list[str], list[str]]]:
    out = []
    made: dict[str, set[str]] = {}
    for cmd in commands(tmp):
        how, reads, writes = check(cmd, made.setdefault(cmd.doc, set()), monkeypatch)
        made[cmd.doc].update(writes)
        out.append((cmd, how, reads, writes))
    return out


def test_every_doc_command_is_checked(tmp_path, monkeypatch):
    rows = checked(tmp_path, monkeypatch)
    docs = {c.doc for c, *_ in rows}
    assert {"README.md", "docs/converter.md", "docs/evaluation.md", "docs/node.md", "bags/README.md"} <= docs, docs
    assert len(rows) >= 40, len(rows)


def test_bare_names_and_missing_files_are_caught(tmp_path, monkeypatch):
    """The rules bite: a bare tool name, a file that is nowhere, an unknown option, an unknown node parameter."""
    made: set[str] = set()
    for argv, why in ((["riann-bag-eval", "bags/x.mcap"], "write .venv/bin/riann-bag-eval"),
                      ([".venv/bin/riann-bag-eval", "run1.mcap"], "run1.mcap does not exist"),
                      ([".venv/bin/riann-bag-convert", "--no-such-option"], "refuses its arguments"),
                      ([".venv/bin/riann_node", "--ros-args", "-p", "nominal_rat:=200"], "no parameter 'nominal_rat'")):
        with pytest.raises((pytest.fail.Exception, AssertionError), match=re.escape(why)):
            check(Command("x.md", 1, argv), made, monkeypatch)
    assert check(Command("x.md", 1, [".venv/bin/riann-bag-eval", "my_run.mcap", "--out", "o"]), made, monkeypatch)[
        0] == "parsed"


# -- run for real ----------------------------------------------------------------------------------------------


def run_or_why_not(cmd: Command, how: str, reads: list[str], ran: set[str], made: set[str], from_broad: set[str],
                   writes: tuple[str, ...] = ()) -> str | None:
    """None: run it; else why it is checked by parsing only. ``ran``/``made``: what earlier commands of the page
    wrote when run / at all; ``from_broad``: what they made from BROAD trials; ``writes``: what it writes."""
    tool = Path(cmd.argv[0]).name
    if any(w.startswith("bags/") for w in writes):
        return "rewrites a bundled bag in bags/ (bags/make_bags.sh)"
    if how == "node help":
        return None
    if how.startswith("workspace"):
        return "a ROS 2 workspace (ros2, colcon): not on this machine"
    if how == "make target":
        return "make demo runs in test_demo_smoke.py, make test is this suite"
    if how == "installed tool":
        return "another package's tool: it exists in .venv/bin"
    if how.startswith("node") or tool == "riann-topic":
        return "starts a node, or needs running nodes (DDS)"
    if "--live" in cmd.argv:
        return "--live: a real-time replay over DDS"
    if any(a.startswith("tcp://") for a in cmd.argv):
        return "a Dask cluster of your own (dask scheduler, dask worker)"
    if "--tune" in cmd.argv or "--rates" in cmd.argv:
        return "long: a tuning grid or several rates"
    for path in reads:
        if _yours(path):
            return f"reads your own file {path}"
        if path == REAL_TRIAL or _made(path, from_broad) or (path.startswith(BROAD) and tool != "riann-bag-convert"):
            return "long: a real trial (make demo runs the one in bags/, test_demo_smoke.py)"
        if path.startswith(BROAD) and (len(reads) > 1 or not Path(ROOT.parent, path[3:]).is_file()):
            return "BROAD: all trials (long), or not on this machine"
        if _made(path, made) and not _made(path, ran):
            return f"reads {path}, made by a command checked by parsing only"
    return None


@pytest.mark.slow
def test_cheap_doc_commands_run(tmp_path, monkeypatch):
    rows = checked(tmp_path / "expand", monkeypatch)
    pages: dict[str, Path] = {}
    ran: dict[str, set[str]] = {}
    made: dict[str, set[str]] = {}
    from_broad: dict[str, set[str]] = {}
    summary = []
    for cmd, how, reads, writes in rows:
        why = run_or_why_not(cmd, how, reads, ran.setdefault(cmd.doc, set()), made.setdefault(cmd.doc, set()),
                             from_broad.setdefault(cmd.doc, set()), tuple(writes))
        made[cmd.doc].update(writes)
        if any(r.startswith(BROAD) or r == REAL_TRIAL for r in reads):
            from_broad[cmd.doc].update(writes)
        summary.append(f"{'ran   ' if why is None else 'parsed'} {cmd}" + (f"   [{why}]" if why else ""))
        if why is not None:
            continue
        if cmd.doc not in pages:
            pages[cmd.doc] = _layout(tmp_path / "run" / _folder(cmd.doc))
            (pages[cmd.doc] / ".venv").symlink_to(ROOT / ".venv")
        env = {k: v for k, v in os.environ.items() if not k.startswith("PYTEST_")}
        r = subprocess.run(cmd.argv, cwd=pages[cmd.doc], env=env, capture_output=True, text=True, timeout=900)
        assert r.returncode == 0, f"{cmd}: exit status {r.returncode}\n{r.stderr[-3000:]}"
        ran[cmd.doc].update(writes)
    print("\n".join(summary))
    assert sum(s.startswith("ran") for s in summary) >= 10, "\n".join(summary)
