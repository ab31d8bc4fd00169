"""How much of the scored span an estimate covers (ROS-free).

The scored span of a sequence is its samples in the score mask with a reference. An estimate covers a sample there
when it has a value at it: the built-in estimators cover every one the input gate lets through; an estimate recorded
by a filter of your own (``--estimate-topic``, ``--estimate-file``) covers the samples within its messages' time span
and ``--max-gap``. Its scores are over what it covers, so an estimate of the easy last tenth of a bag would rank
above a filter that ran all of it: a recorded estimate that covers less than :data:`MIN_COVERAGE` of the span is
**not ranked** — left out of the summary tables (and of tuning and the groups of ``--compare``), with a warning;
its rows stay in results.csv / results.json with their coverage (``coverage``,
:attr:`~riann_ros.evaluation.results.ResultRow.coverage`) and scores.
"""

from __future__ import annotations

from collections.abc import Sequence

from riann_ros.evaluation.results import RECORDED, ResultRow

MIN_COVERAGE = 0.9  # a recorded estimate covering less of the scored span is not ranked


def ranked(row: ResultRow) -> bool:
    """Whether ``row`` takes part in rankings: every built-in estimator's; a recorded estimate's when it covers at
    least :data:`MIN_COVERAGE` of the scored span."""
    c = row.coverage
    return row.estimator_name != RECORDED or c is None or c >= MIN_COVERAGE


def warnings(rows: Sequence[ResultRow]) -> list[str]:
    """A warning per recorded estimate that is not ranked (:func:`ranked`), naming its sequence and its coverage."""
    out = []
    for r in rows:
        c = r.coverage
        if c is not None and not ranked(r):
            span = r.score.n_scored + r.score.n_unestimated
            out.append(f"{r.sequence}: the estimate {r.estimator} covers {100 * c:.1f} % of the scored span "
                       f"({r.score.n_scored} of {span} samples), less than {100 * MIN_COVERAGE:.0f} %: its scores "
                       "are over what it covers, and it is not ranked in the summary")
    return out


def recorded_lines(rows: Sequence[ResultRow]) -> list[str]:
    """Per recorded estimate (label), its coverage of the scored span over the sequences: the least, and
    how many sequences rank it (empty when the run scored no recorded estimate)."""
    rec = [r for r in rows if r.estimator_name == RECORDED and r.coverage is not None]
    out = []
    for label in dict.fromkeys(r.estimator for r in rec):
        mine = [r for r in rec if r.estimator == label]
        low = min(c for r in mine if (c := r.coverage) is not None)
        n_ranked = sum(ranked(r) for r in mine)
        out.append(f"estimate {label}: covers {100 * low:.1f} % of the scored span at least "
                   f"({len(mine)} row(s), {n_ranked} ranked; ranked from {100 * MIN_COVERAGE:.0f} %)")
    return out
