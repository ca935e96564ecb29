"""studies/krylov_contact.py: Krylov iterations against the contact stiffness."""

import pytest

from studies import krylov_contact


@pytest.mark.serial  # starts its own processes
def test_softer_contact_takes_no_more_iterations_and_the_table_lists_each_case():
    """With the plain rigid motions as near-nullspace the stiff contact block costs iterations (a softer one takes no
    more); the table lists each case with its near-nullspace."""
    # each case in its own process, as the study runs them (run_case_apart says why)
    stiff, soft = krylov_contact.run_case_apart(3, 1e-10, "rigid"), krylov_contact.run_case_apart(3, 1e-3, "rigid")
    assert stiff["dofs"] == soft["dofs"] == 3 * 4 ** 3 and stiff["level0"] > 0 and stiff["steps"] > 0
    assert soft["steps"] <= stiff["steps"]
    default = krylov_contact.run_case_apart(3, 1e-10)
    assert default["nullspace"] == "contact" and default["step_s"] > 0
    text = krylov_contact.table([stiff, soft, default])
    assert "| 3 | 192 | 1e-10 | rigid |" in text and "| 3 | 192 | 0.001 | rigid |" in text
    assert "| 3 | 192 | 1e-10 | contact |" in text


@pytest.mark.serial
def test_bad_options_are_one_line_and_exit_2(capsys):
    assert krylov_contact.main(["--mu", "0"]) == 2
    err = capsys.readouterr().err
    assert err == "error: --mu 0: must be > 0\n"


@pytest.mark.serial  # starts its own processes
def test_the_amg_comparison_runs_each_amg_and_tables_ratios_to_the_solvers():
    """--amg: each run uses its own preconditioner (the same solution to the solver's tolerance), and the table reads
    step time and peak memory as ratios to the solver's AMG (gamg) on the same case."""
    gamg = krylov_contact.run_case_apart(4, 1e-10, "contact", "gamg")
    ml = krylov_contact.run_case_apart(4, 1e-10, "contact", "ml")
    assert (gamg["amg"], ml["amg"]) == ("gamg", "ml") and ml["peak_mib"] > 0 and gamg["peak_mib"] > 0
    assert ml["contact_force"] == pytest.approx(gamg["contact_force"], rel=1e-8)
    assert (gamg["level0"], gamg["steps"]) != (ml["level0"], ml["steps"])  # another preconditioner ran
    text = krylov_contact.amg_table([ml, gamg])
    assert "| 4 | 375 | 1e-10 | gamg |" in text and "| 1.00 |" in text
    assert f"| 4 | 375 | 1e-10 | ml | {ml['level0']:.1f} | {ml['steps']:.1f} |" in text


def test_a_failing_solve_is_a_row_of_the_table(monkeypatch):
    """A case whose displacement solve fails (a preconditioner that breaks down) reports the failure, the study goes
    on and the table says so."""
    from solver.errors import DisplacementSolveError

    def fails(model, out):
        raise DisplacementSolveError("SNES", "DIVERGED_LINEAR_SOLVE", 1, [1.0, 1e8], 1e-10, linear_reason=-8)

    good = krylov_contact.run_case(3, 1e-10, "contact", "gamg")
    monkeypatch.setattr("solver.io.results.run", fails)
    bad = krylov_contact.run_case(3, 1e-10, "contact", "gamg-reuse")
    assert "linear solve -8" in bad["failed"] and bad["dofs"] == good["dofs"] == 192
    text = krylov_contact.amg_table([good, bad])
    assert "| 3 | 192 | 1e-10 | gamg-reuse | failed: " in text and "| 3 | 192 | 1e-10 | gamg |" in text
    assert "| 3 | 192 | 1e-10 | contact | failed: " in krylov_contact.table([bad])  # the near-nullspace table too
    assert krylov_contact._merge([good, bad]) is bad  # a case with a failed repeat is a failed case
