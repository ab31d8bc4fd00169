"""The evo example of docs/evaluation.md ("Estimates as files for evo"), run for real: its commands, and every figure
the page shows of them, come from here.

Usage::

    .venv/bin/python bench/evo_example.py            # run the commands, write docs/results/evo.json
    .venv/bin/python bench/evo_example.py --check    # run them, exit 1 when a figure differs from the committed one
    .venv/bin/python bench/results_tables.py         # then: the page's blocks from docs/results/evo.json

:data:`COMMANDS` run in a scratch folder laid out as the repository root (``bags/`` and ``.venv`` linked; ``HOME``
there too, for evo's settings file). ``docs/results/evo.json`` keeps the commands and what each printed (stdout), and
from riann-bag-eval's results.json the rows' figures the prose cites. The page's ``<!-- results:evo-… -->`` blocks
(the commands, riann-bag-eval's total-angle table, evo_ape's and evo_traj's output, the figures in the text) are
:data:`TABLES`, which bench/results_tables.py renders; test_results_tables.py fails when the page differs.
"""

from __future__ import annotations

import argparse
import json
import math
import os
import re
import shlex
import subprocess
import sys
import tempfile
from collections.abc import Callable
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
RESULT = ROOT / "docs" / "results" / "evo.json"
TRIAL = "21_undisturbed_fast_combined.as-recorded"
SYNTH = "synthetic_rotation_seed2_100hz.as-recorded"
COMMANDS = [
    ".venv/bin/riann-bag-eval bags/broad_21_undisturbed_fast_combined.mcap -e riann,vqf -s as-recorded "
    "--write-estimates est --out eval21",
    f".venv/bin/evo_ape tum est/{TRIAL}.reference.tum est/{TRIAL}.riann.tum -r angle_deg",
    f".venv/bin/evo_ape tum est/{TRIAL}.reference.tum est/{TRIAL}.vqf.tum -r angle_deg",
    f".venv/bin/evo_traj tum est/{TRIAL}.riann.tum est/{TRIAL}.vqf.tum --ref est/{TRIAL}.reference.tum",
    ".venv/bin/riann-bag-eval bags/synthetic_rotation_100hz.mcap -e riann -s as-recorded --heading "
    "--write-estimates est6 --out eval6",
    f".venv/bin/evo_ape tum est6/{SYNTH}.reference.tum est6/{SYNTH}.riann.tum -r angle_deg --align_origin",
]
KEPT = ("n_scored", "rmse_deg", "heading_rmse_deg", "total_rmse_deg")  # of each results.json row
TOLERANCE_DEG = 1e-4  # --check: a figure further from the committed one is a change


def run(workdir: Path) -> dict:
    """Run :data:`COMMANDS` in ``workdir`` (a scratch repository layout); their outputs and the results' figures."""
    (workdir / "bags").symlink_to(ROOT / "bags")
    (workdir / ".venv").symlink_to(ROOT / ".venv")
    env = {**os.environ, "HOME": str(workdir)}
    outputs = []
    for cmd in COMMANDS:
        r = subprocess.run(shlex.split(cmd), cwd=workdir, env=env, capture_output=True, text=True, timeout=1800)
        if r.returncode != 0:
            raise RuntimeError(f"{cmd}: exit status {r.returncode}\n{r.stderr[-2000:]}")
        # evo's notice of the settings file it made on its first run names the scratch folder: not kept
        outputs.append("".join(ln for ln in r.stdout.splitlines(keepends=True) if "settings.json" not in ln))
    rows = {}
    for run_dir in ("eval21", "eval6"):
        for row in json.loads((workdir / run_dir / "results.json").read_text())["results"]:
            rows[f"{run_dir}/{row['estimator']}"] = {k: row.get(k) for k in KEPT}
    from importlib import metadata

    return {"commands": COMMANDS, "outputs": outputs, "rows": rows, "evo": metadata.version("evo")}


def _numbers(text: str) -> list[float]:
    """The figures of an output, without the run's wall time (``… input(s) evaluated in 28.6 s``)."""
    kept = "\n".join(ln for ln in text.splitlines() if " evaluated in " not in ln)
    return [float(x) for x in re.findall(r"-?\d+\.\d+", kept)]


def differences(old: dict, new: dict) -> list[str]:
    """What differs between two results (figures beyond :data:`TOLERANCE_DEG`, anything else exactly)."""
    out = []
    if old.get("commands") != new["commands"]:
        out.append("the commands")
    for k, (a, b) in enumerate(zip(old.get("outputs", []), new["outputs"], strict=False)):
        na, nb = _numbers(a), _numbers(b)
        if len(na) != len(nb) or any(abs(x - y) > TOLERANCE_DEG for x, y in zip(na, nb, strict=True)):
            out.append(f"the output of {COMMANDS[k]}")
    for key, row in new["rows"].items():
        for f, v in row.items():
            w = (old.get("rows", {}).get(key) or {}).get(f)
            if (v is None) != (w is None) or (v is not None and not math.isclose(v, w, abs_tol=TOLERANCE_DEG)):
                out.append(f"{key} {f}: {w} committed, {v} now")
    return out


# ---- the page's blocks (bench/results_tables.py renders them) ------------------------------------------------------
def _load() -> dict:
    return json.loads(RESULT.read_text())


def _fence(lang: str, text: str) -> str:
    return f"```{lang}\n{text.rstrip()}\n```"


def _section(text: str, title: str) -> str:
    """The table of riann-bag-eval's stdout that starts with ``title`` (up to its blank line)."""
    start = text.index(title)
    end = text.find("\n\n", start)
    return text[start:] if end < 0 else text[start:end]


def _ape(k: int) -> dict[str, float]:
    return {m[1]: float(m[2]) for m in re.finditer(r"^\s*(\w+)\t([-\d.]+)$", _load()["outputs"][k], re.M)}


def commands() -> str:
    return _fence("bash", "\n".join(_load()["commands"]))


def total_table() -> str:
    return _fence("text", _section(_load()["outputs"][0], "total angle error (°) per sequence"))


def ape_riann() -> str:
    return _fence("text", _load()["outputs"][1].strip("\n"))


def ape_vqf() -> str:
    a = _ape(2)
    return ", ".join(f"{k} {a[k]:.6f}" for k in ("max", "mean", "median", "min", "rmse", "std"))


def traj() -> str:
    return _fence("text", _load()["outputs"][3].strip("\n"))


def evo_version() -> str:
    return f"evo {_load()['evo']}"


def json_figures() -> str:
    rows = _load()["rows"]
    r, v = rows["eval21/riann"], rows["eval21/vqf"]
    return (f"`total_rmse_deg` {r['total_rmse_deg']:.7f} (RIANN) and {v['total_rmse_deg']:.7f} (VQF) over "
            f"{r['n_scored']:,} scored samples".replace(",", " "))


def inclination_vs_total() -> str:
    rows = _load()["rows"]
    r, v = rows["eval21/riann"], rows["eval21/vqf"]
    return (f"{r['rmse_deg']:.2f}° (RIANN) and {v['rmse_deg']:.2f}° (VQF) here, against {r['total_rmse_deg']:.2f}° "
            f"and {v['total_rmse_deg']:.2f}° total — the rest is the heading ({r['heading_rmse_deg']:.2f}° and "
            f"{v['heading_rmse_deg']:.2f}° RMSE)")


def total_6d() -> str:
    return f"{_load()['rows']['eval6/riann']['total_rmse_deg']:.2f}°"


def align_origin() -> str:
    return f"{_ape(5)['rmse']:.2f}°"


TABLES: dict[str, Callable[[], str]] = {
    "evo-commands": commands, "evo-total-table": total_table, "evo-ape-riann": ape_riann, "evo-ape-vqf": ape_vqf,
    "evo-traj": traj, "evo-version": evo_version, "evo-json": json_figures, "evo-inclination": inclination_vs_total,
    "evo-6d-total": total_6d, "evo-align-origin": align_origin,
}


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--check", action="store_true", help="only compare with docs/results/evo.json; exit 1 on a change")
    args = ap.parse_args(argv)
    with tempfile.TemporaryDirectory(prefix="evo_example.") as tmp:
        new = run(Path(tmp))
    if args.check:
        diff = differences(_load(), new)
        for d in diff:
            print(f"differs: {d}", file=sys.stderr)
        return 1 if diff else 0
    RESULT.write_text(json.dumps(new, indent=1, ensure_ascii=False) + "\n")
    print(f"wrote {RESULT.relative_to(ROOT)}; now .venv/bin/python bench/results_tables.py")
    return 0


if __name__ == "__main__":
    sys.exit(main())
