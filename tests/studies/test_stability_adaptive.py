"""studies/stability_adaptive.py: the stability map's adaptive columns, the uniform steps at an error and the
failure rule (more steps than uniform for the same error), and one small cell run end to end."""

import math

import pytest

from studies.stability_adaptive import adaptive_group, failure_of, uniform_steps_at

pytestmark = pytest.mark.serial  # the study runs in one process: on 2 ranks each would run the same checks again

UNIFORM = [(4e-3, 10), (2e-3, 20), (1e-3, 40)]  # order 1: error x steps = 0.04


def test_the_uniform_steps_at_an_error_are_interpolated_and_extrapolated_along_the_column():
    steps, out = uniform_steps_at(1.5e-3, UNIFORM)
    assert not out and steps == pytest.approx(0.04 / 1.5e-3, rel=0.05)
    steps, out = uniform_steps_at(2.5e-4, UNIFORM)  # below the finest: the line of the two nearest runs
    assert out and steps == pytest.approx(160, rel=1e-9)
    assert math.isnan(uniform_steps_at(1e-3, UNIFORM[:1])[0])


def _row(**kw):
    row = {"status": "converged", "tolerance": 2e-3, "time_error": 5e-4, "trials": 70, "uniform_steps": 20,
           "uniform_time_error": 2e-3, "steps_ratio": 70 / 80, "extrapolated": False}
    row.update(kw)
    return row


def test_a_cell_fails_where_it_needs_more_steps_for_the_same_error_or_misses_its_tolerance():
    assert failure_of(_row()) == ""  # more trials than the cell's uniform run, but for a 4x smaller error
    assert failure_of(_row(steps_ratio=1.3)) == "more steps than uniform"
    assert failure_of(_row(time_error=2e-3, steps_ratio=70 / 20)) == "more steps than uniform"
    assert failure_of(_row(time_error=3e-3, trials=15, steps_ratio=0.5)) == "error above the tolerance"
    assert failure_of(_row(steps_ratio=1.3, extrapolated=True)) == "more steps than uniform (extrapolated)"
    assert failure_of(_row(status="diverged")) == "stopped"


def test_a_small_column_runs_and_its_adaptive_runs_meet_their_tolerance():
    from studies import REPO

    rows = adaptive_group((REPO / "configs" / "example1.toml", "example1", 1e-10, 4, [0.1, 0.05], 0.0125, 50))
    assert [r["k"] for r in rows] == [0.1, 0.05]
    for r in rows:
        assert r["status"] == "converged" and r["uniform_steps"] == round(1 / r["k"])
        assert 0 < r["time_error"] <= r["tolerance"] == r["uniform_time_error"]
        assert r["trials"] >= r["levels"] > 0 and math.isfinite(r["steps_ratio"])


def test_a_cell_within_the_references_own_error_is_not_judged():
    """At order 1 the error measured against a reference of step k_ref is C (k - k_ref): the reference's own is
    C k_ref, and an adaptive error below twice that is not judged (no failure claimed either way)."""
    from studies.stability_adaptive import judge, reference_error

    assert reference_error(0.01, [(0.1, 0.9), (0.05, 0.4)]) == pytest.approx(0.4 * 0.01 / 0.04)  # C = 10: 0.1
    cells = [dict(_row(), scene="s", mu=1.0, n=8, method="adaptive", k=k, uniform_time_error=e, time_error=a, tolerance=e,
                  steps_ratio=3.0) for k, e, a in ((0.1, 0.9, 0.5), (0.05, 0.4, 0.15))]
    judge(cells, 0.01)
    assert [c["judged"] for c in cells] == [True, False]  # 0.5 >= 2 x 0.1; 0.15 < 0.2
    assert cells[0]["adaptive_failure"] == "more steps than uniform" and cells[1]["adaptive_failure"] == ""
