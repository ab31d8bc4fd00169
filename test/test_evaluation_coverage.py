"""How much of the scored span an estimate covers (riann_ros.evaluation.coverage): a recorded estimate covering less
than MIN_COVERAGE is not ranked (not in the summary), warned about and marked in the per-sequence tables; the
built-in estimators always rank."""

from __future__ import annotations

from riann_ros.evaluation import coverage
from riann_ros.evaluation.aggregate import aggregate
from riann_ros.evaluation.results import RECORDED, ResultRow
from riann_ros.evaluation.scoring import Score
from riann_ros.evaluation.seq_tables import per_sequence_markdown


def row(estimator: str, name: str, n_scored: int, n_unestimated: int, rmse: float, seq: str = "s1") -> ResultRow:
    return ResultRow(sequence=seq, dataset="d", source=f"{seq}.mcap", scenario="as-recorded", rate="native",
                     rate_hz=100.0, resampled=False, estimator=estimator, estimator_name=name, mode="offline",
                     score=Score(n_samples=1000, n_scored=n_scored, n_unestimated=n_unestimated, rmse_deg=rmse,
                                 max_err_deg=2 * rmse))


def test_a_recorded_estimate_below_the_share_is_not_ranked():
    tail = row("mine", RECORDED, 100, 900, 0.3)  # 10 %: the easy last tenth
    most = row("theirs", RECORDED, 900, 100, 0.9)  # 90 %: ranked
    gated = row("vqf", "vqf", 500, 500, 2.0)  # a built-in estimator whose gate rejected half: ranked all the same
    assert (tail.coverage, most.coverage, gated.coverage) == (0.1, 0.9, 0.5)
    assert [coverage.ranked(r) for r in (tail, most, gated)] == [False, True, True]
    assert [g.estimator for g in aggregate([tail, most, gated])] == ["theirs", "vqf"]
    (warning,) = coverage.warnings([tail, most, gated])
    assert warning.startswith("s1: the estimate mine covers 10.0 % of the scored span (100 of 1000 samples), less "
                              "than 90 %")
    assert coverage.recorded_lines([tail, most, gated]) == [
        "estimate mine: covers 10.0 % of the scored span at least (1 row(s), 0 ranked; ranked from 90 %)",
        "estimate theirs: covers 90.0 % of the scored span at least (1 row(s), 1 ranked; ranked from 90 %)"]
    table = "\n".join(per_sequence_markdown([tail, most, gated]))
    assert "| s1 | 0.30 (covers 10 %: not ranked) | 0.90 | 2.00 |" in table
    assert tail.to_dict()["coverage"] == 0.1


def test_a_row_without_a_reference_has_no_coverage():
    free = row("vqf", "vqf", 0, 0, float("nan"))
    free.has_reference = False
    assert free.coverage is None and coverage.ranked(free) and coverage.warnings([free]) == []
