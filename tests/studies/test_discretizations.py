"""The pure parts of the discretization study: slopes and the order table."""

import math

import pytest

from studies.discretizations import SERIES, orders_markdown, slope

pytestmark = pytest.mark.serial  # no MPI here: on 2 ranks each would run the same checks again


def test_slope_of_a_power_law_and_of_too_few_points():
    assert slope([1, 2, 4], [3, 12, 48]) == pytest.approx(2.0)
    assert math.isnan(slope([1], [2]))
    assert slope([1, 2, 4, 8], [1, 0.5, float("nan"), 0.125]) == pytest.approx(-1.0)  # NaN points are skipped


def test_order_table_markdown_lists_every_row():
    table = {"h": {"P1": {"ns": [8, 16], "errors": [2e-2, 1e-2], "rate": 1.0},
                   "P2": {"ns": [8, 16], "errors": [4e-3, 2e-3], "rate": 1.0}},
             "k": {label: {"ks": [0.1, 0.05], "errors": [1e-3, 2.5e-4], "rates": [2.0], "rate": 2.0} for label in SERIES}}
    text = orders_markdown(table, 16)
    assert "| P2 | 4.00e-03 | 2.00e-03 | 1.00 |" in text
    assert sum(line.startswith("| P") for line in text.splitlines()) == 2 + len(SERIES)
