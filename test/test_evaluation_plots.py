"""riann-bag-eval's plots (riann_ros.evaluation.plots): RMSE box plots and RMSE against rate on linear axes, the
roll/pitch plot per sequence, a panel for every perturbation condition, each estimator's colour fixed whatever
the order."""

from __future__ import annotations

import re
from pathlib import Path

import numpy as np
import pytest

from riann_ros.cli.evaluate import main


def _capture(monkeypatch) -> list:
    from riann_ros.evaluation import plots

    figs: list = []
    monkeypatch.setattr(plots, "_save", lambda fig, out_dir, stem: figs.append((stem, fig)) or [])
    return figs


@pytest.mark.parametrize("n", [1, 3])
def test_boxplots_show_every_sequence_on_a_linear_axis(three, n, monkeypatch):
    from riann_ros import evaluation as ev
    from riann_ros.evaluation import plots

    settings = ev.EvalSettings(estimators=ev.parse_estimators("madgwick,vqf"), scenarios=["realistic", "as-recorded"])
    rows = [r for b in three[:n] for r in ev.evaluate_source(b, settings).rows]
    figs = _capture(monkeypatch)
    plots.plot_boxes(rows, Path("."))
    (_, fig), = figs
    axes = [a for a in fig.axes if a.get_title()]
    assert [a.get_title() for a in axes] == ["realistic", "as-recorded"]
    for ax in axes:
        assert ax.get_yscale() == "linear" and ax.get_ylim()[0] == 0.0
        assert ax.get_ylim()[1] >= max(r.rmse_deg for r in rows)  # nothing clipped
        points = sum(len(c.get_offsets()) for c in ax.collections)
        assert points == 2 * n  # every sequence of both estimators is a point
        assert len(ax.patches) == (2 if n >= plots.BOX_MIN_N else 0)  # boxes only from BOX_MIN_N sequences on
    legend = [t.get_text() for t in fig.legends[0].get_texts()]
    assert legend == [f"madgwick (n={n})", f"vqf (n={n})"]


def test_rmse_vs_rate_is_linear(three, monkeypatch):
    from riann_ros import evaluation as ev
    from riann_ros.evaluation import plots

    settings = ev.EvalSettings(estimators=ev.parse_estimators("madgwick"), scenarios=["realistic"], rates=[50.0, 100.0])
    rows = ev.evaluate_source(three[0], settings).rows
    figs = _capture(monkeypatch)
    plots.plot_rmse_vs_rate(rows, Path("."))
    (_, fig), = figs
    assert fig.axes[0].get_yscale() == "linear" and fig.axes[0].get_ylim()[0] == 0.0
    assert fig.legends[0].get_texts()[0].get_text() == "madgwick (n=1)"


@pytest.mark.slow
def test_roll_pitch_plot_per_sequence(three, tmp_path):
    out = tmp_path / "all"
    assert main([*map(str, three), "-e", "madgwick,vqf", "--plot-sequence", "all", "--out", str(out), "-q"]) == 0
    for i in range(3):
        assert (out / f"roll_pitch_s{i}.png").is_file() and (out / f"roll_pitch_s{i}.svg").is_file()
    assert (out / "error_over_time.png").is_file()  # stays
    assert "roll_pitch_s2.png" in (out / "report.md").read_text()
    first = tmp_path / "first"
    assert main([*map(str, three), "-e", "madgwick", "--out", str(first), "-q"]) == 0
    assert sorted(p.name for p in first.glob("roll_pitch_*.png")) == ["roll_pitch_s0.png"]


def test_roll_pitch_plot_content(three, monkeypatch):
    from riann_ros import evaluation as ev
    from riann_ros.evaluation import plots

    settings = ev.EvalSettings(estimators=ev.parse_estimators("madgwick,vqf"), scenarios=["realistic", "as-recorded"],
                               series_for="*")
    res = ev.evaluate_source(three[1], settings)
    figs = _capture(monkeypatch)
    plots.plot_attitude(res.series, Path("."))
    (stem, fig), = figs
    assert stem == "roll_pitch_s1"
    roll, pitch, err = fig.axes[:3]
    assert (roll.get_ylabel(), pitch.get_ylabel(), err.get_ylabel()) == ("roll (°)", "pitch (°)", "e_α (°)")
    assert [ln.get_label() for ln in roll.lines] == ["reference", "madgwick", "vqf"]
    assert "as-recorded" in roll.get_title()  # the recording as it is, when evaluated
    ref = res.series["attitude"]["as-recorded"]["reference"]
    assert np.nanmax(np.abs(ref[:, 0])) == pytest.approx(25.0, abs=0.5)  # the synthetic roll swings ±25°
    assert np.nanmax(np.abs(ref[:, 1])) < 0.5


def _svg_ids(path: Path) -> list[str]:
    return re.findall(r'id="((?:panel|estimator):[^"]*)"', path.read_text())


def _svg_colour(path: Path, gid: str) -> str:
    """The first colour (a fill or stroke other than black edges) of the SVG group with this id."""
    text = path.read_text()
    start = text.index(f'id="{gid}"')
    group = text[start:text.index("</g>", start)]
    styles = " ".join(re.findall(r'style="([^"]*)"', group))
    return next(c for c in re.findall(r"(?:stroke|fill): (#[0-9a-f]{6})", styles) if c != "#000000")


@pytest.mark.slow
def test_every_perturbation_condition_is_plotted(three, tmp_path, capsys):
    out = tmp_path / "all"
    args = [*map(str, three[:2]), "-e", "madgwick", "-s", "as-recorded,realistic", "-p", "none", "-p",
            "jitter:10/20/30ms"]
    assert main([*args, "--out", str(out), "-q"]) == 0
    panels = [i for i in _svg_ids(out / "rmse_boxplots.svg") if i.startswith("panel:")]
    assert panels == ["panel:realistic|none", "panel:as-recorded|none", "panel:realistic|jitter:10/20/30ms",
                      "panel:as-recorded|jitter:10/20/30ms"]
    assert sorted(i for i in _svg_ids(out / "error_over_time.svg") if i.startswith("panel:")) == sorted(panels)
    assert (out / "roll_pitch_s0.svg").is_file() and (out / "roll_pitch_s0_jitter_10_20_30ms.svg").is_file()
    assert "roll_pitch_s0_jitter_10_20_30ms.png" in (out / "report.md").read_text()
    chosen = tmp_path / "chosen"  # the user picks the conditions to plot
    assert main([*args, "--plot-perturb", "jitter:10/20/30ms", "--out", str(chosen), "-q"]) == 0
    assert [i for i in _svg_ids(chosen / "rmse_boxplots.svg") if i.startswith("panel:")] == [
        "panel:realistic|jitter:10/20/30ms", "panel:as-recorded|jitter:10/20/30ms"]
    assert sorted(p.name for p in chosen.glob("roll_pitch_*.svg")) == ["roll_pitch_s0_jitter_10_20_30ms.svg"]
    assert main([*args, "--plot-perturb", "jitter:5ms", "--out", str(tmp_path / "x"), "-q"]) == 2
    assert "not an evaluated condition" in capsys.readouterr().err


@pytest.mark.slow
def test_estimator_colours_do_not_depend_on_the_order(three, tmp_path):
    from riann_ros.evaluation import plots

    colours = []
    for order in ("madgwick,vqf,madgwick:beta=0.1", "madgwick:beta=0.1,vqf,madgwick"):
        out = tmp_path / order.replace(":", "_").replace(",", "_")
        assert main([*map(str, three), "-e", order, "-s", "as-recorded", "--out", str(out), "-q"]) == 0
        colours.append({(f.name, e): _svg_colour(out / f.name, f"estimator:{e}")
                        for f in (out / "roll_pitch_s0.svg", out / "rmse_boxplots.svg", out / "error_over_time.svg")
                        for e in ("madgwick", "vqf", "madgwick(beta=0.1)")})
    assert colours[0] == colours[1]
    assert colours[0][("roll_pitch_s0.svg", "madgwick")] == plots.FIXED_COLORS["madgwick"]
    assert colours[0][("rmse_boxplots.svg", "vqf")] == plots.FIXED_COLORS["vqf"]
    assert colours[0][("roll_pitch_s0.svg", "madgwick(beta=0.1)")] not in plots.FIXED_COLORS.values()


def _min_delta_e(colours: dict[str, str]) -> float:
    from riann_ros.evaluation.plots import lab

    c = lab(list(colours.values()))
    d = np.sqrt(((c[:, None] - c[None]) ** 2).sum(-1))
    np.fill_diagonal(d, np.inf)
    return float(d.min())


def test_colours_of_one_figure_differ_by_min_delta_e():
    """Any two labels of a figure (up to 16: the four estimators, variants of them such as a tuning grid, recorded
    topics, files, comparisons) are at least MIN_DELTA_E apart in CIELAB; the built-in estimators keep their colours,
    a lone variant is a shade of its estimator's, and the order of the labels does not matter."""
    from riann_ros.evaluation import plots
    from riann_ros.evaluation.specs import DEFAULT_GRIDS, make_label

    bases = list(plots.FIXED_COLORS)
    variants = [make_label(name, {p: v}) for name, grid in DEFAULT_GRIDS.items() for p, vals in grid.items()
                for v in vals]
    others = ["/my_filter/imu", "vins", "recorded:/imu/data", "madgwick → madgwick(beta=0.1)", "run_a", "ekf"]
    rng = np.random.default_rng(0)
    for trial in range(300):
        n = int(rng.integers(2, 17))
        pool = bases + variants + others
        labels = list(rng.choice(pool, size=min(n, len(pool)), replace=False))
        colours = plots.estimator_colors(labels)
        assert set(colours) == set(labels)
        assert _min_delta_e(colours) >= plots.MIN_DELTA_E, (trial, colours)
        assert all(colours[b] == plots.FIXED_COLORS[b] for b in bases if b in labels)
        rng.shuffle(labels)
        assert plots.estimator_colors(labels) == colours  # whatever the order
    # the case that was hard to tell apart: vqf and one variant of it, a lighter or darker green
    two = plots.estimator_colors(["vqf(tau_acc=1)", "vqf"])
    assert _min_delta_e(two) >= plots.MIN_DELTA_E
    shade = plots.lab([two["vqf(tau_acc=1)"]])[0]
    dist = {b: float(np.linalg.norm(shade - plots.lab([c])[0])) for b, c in plots.FIXED_COLORS.items()}
    assert min(dist, key=lambda b: dist[b]) == "vqf", dist
    # a whole default tuning grid beside the four (47 labels): beyond the palette's distance, still all different
    many = plots.estimator_colors(bases + variants)
    assert len(set(many.values())) == len(many)


def test_colour_candidates_are_visible_and_not_grey():
    from riann_ros.evaluation import plots

    c = plots.lab(list(plots.CANDIDATES))
    assert np.all(np.hypot(c[:, 1], c[:, 2]) >= 20) and np.all(c[:, 0] <= 85)  # chroma, lightness L*
    assert not set(plots.CANDIDATES) & set(plots.FIXED_COLORS.values()) and len(set(plots.CANDIDATES)) == 54
    assert plots.lab(["#ffffff"])[0] == pytest.approx([100, 0, 0], abs=0.05)  # D65 white
    assert plots.lab(["#ff0000"])[0] == pytest.approx([53.24, 80.09, 67.20], abs=0.1)  # sRGB red, published Lab
