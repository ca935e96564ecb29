"""studies/krylov_contact.py: Krylov iterations against the contact stiffness."""

import pytest

from studies import krylov_contact


def test_softer_contact_takes_no_more_iterations_and_the_table_lists_each_case():
    stiff, soft = krylov_contact.run_case(3, 1e-10), krylov_contact.run_case(3, 1e-3)
    assert stiff["dofs"] == soft["dofs"] == 3 * 4 ** 3 and stiff["level0"] > 0 and stiff["steps"] > 0
    assert soft["steps"] <= stiff["steps"]
    text = krylov_contact.table([stiff, soft])
    assert "| 3 | 192 | 1e-10 | 1e+10 |" in text and "| 3 | 192 | 0.001 | 1000 |" in text


@pytest.mark.serial
def test_bad_options_are_one_line_and_exit_2(capsys):
    assert krylov_contact.main(["--mu", "0"]) == 2
    err = capsys.readouterr().err
    assert err == "error: --mu 0: must be > 0\n"
