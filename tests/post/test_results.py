"""Post-processing helpers: point values on any rank, reading the CSV back (the series: test_xdmf)."""

import pytest
from conftest import point_value, unit_mesh
from dolfinx import fem

from solver.post.results import read_csv


def test_point_value_is_the_same_on_every_rank_and_refuses_outside(comm):
    mesh = unit_mesh(comm, 4)
    f = fem.Function(fem.FunctionSpace(mesh, ("CG", 1)))
    f.interpolate(lambda x: 1.0 + 2.0 * x[0] - x[1])
    assert point_value(f, [0.3, 0.7])[0] == pytest.approx(1.0 + 0.6 - 0.7)
    with pytest.raises(ValueError, match="outside"):
        point_value(f, [2.0, 0.5])


def test_read_csv(tmp_path):
    (tmp_path / "t.csv").write_text("step,t\n0,0.0\n1,0.25\n")
    assert read_csv(tmp_path / "t.csv") == [{"step": 0.0, "t": 0.0}, {"step": 1.0, "t": 0.25}]
