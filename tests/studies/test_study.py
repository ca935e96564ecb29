"""The pure parts of the study command: the Pareto front and the status of a run."""

import math

from solver.errors import DamageSolveError, DisplacementSolveError
from studies.study import _status, pareto


def test_pareto_keeps_the_points_no_other_beats_in_both():
    pts = [(1.0, 5.0), (2.0, 3.0), (2.5, 4.0), (3.0, 1.0), (0.5, 9.0), (3.0, 1.0)]
    front = pareto(pts)
    assert sorted(front) == [0, 1, 3, 4]
    assert pareto([]) == []
    assert pareto([(1.0, math.inf)]) == []  # an infinite error is never on the front


def test_status_of_a_run_comes_from_the_failure_type_and_fields():
    assert _status(None) == ("converged", "")
    err = DisplacementSolveError("penalty_duality", "DIVERGED_STAGNATION", 21, [1.0], 1e-9).at(3, 0.3)
    status, reason = _status(err)
    assert status == "stagnated" and reason.startswith("step 3, t = 0.3")
    assert _status(DamageSolveError("SEMI_IMPLICIT_UNSTABLE").at(2, 0.2))[0] == "damage_failed"


def test_a_run_of_some_methods_keeps_the_other_methods_rows(tmp_path):
    """``study stability --methods newton_energy`` adds that method to stability.csv without dropping the
    methods (or cells) it did not run again, and replaces the rows of the ones it did."""
    from studies.study import _kept_rows, _write_csv

    old = [{"scene": "hard", "method": m, "mu": 1e-10, "n": 8, "k": 0.1, "status": "converged", "seconds": 1.0}
           for m in ("newton", "fixed_point")]
    _write_csv(old, tmp_path / "stability.csv")
    new = [{**old[0], "method": "newton", "seconds": 2.0}, {**old[0], "method": "newton_energy"}]
    rows = _kept_rows(tmp_path / "stability.csv", new)
    assert sorted(r["method"] for r in rows) == ["fixed_point", "newton", "newton_energy"]
    assert [r["seconds"] for r in rows if r["method"] == "newton"] == [2.0]
    assert _kept_rows(tmp_path / "none.csv", new) == new
    # a cell measured again replaces only that cell of the method
    other = {**old[0], "k": 0.05}
    _write_csv([*old, other], tmp_path / "stability.csv")
    rows = _kept_rows(tmp_path / "stability.csv", new)
    assert sorted((r["method"], r["k"]) for r in rows if r["method"] == "newton") == [("newton", 0.05), ("newton", 0.1)]
