"""The convergence study: exact nested transfer, and first-order rates in h and in k."""

import numpy as np
import pytest
from conftest import ROOT, point_value
from dolfinx import fem, mesh
from mpi4py import MPI

from solver.mesh.geometry import _DIAGONAL
from studies.convergence import grid_order, paper_error, prolongation, rates, study

pytestmark = pytest.mark.serial  # the study runs in one process


@pytest.mark.parametrize("diagonal", ["right", "left"])
def test_prolongation_is_exact_p1_transfer(diagonal):
    nc, nf = 4, 12
    corners = ((0.0, 0.0), (1.0, 1.0))
    mc = mesh.create_unit_square(MPI.COMM_SELF, nc, nc, diagonal=_DIAGONAL[diagonal])
    Vc = fem.FunctionSpace(mc, ("CG", 1))
    f = fem.Function(Vc)
    f.interpolate(lambda x: np.sin(3 * x[0]) * np.exp(x[1]) + x[0] * x[1] ** 2)
    grid_c = np.empty((nc + 1) ** 2)
    grid_c[grid_order(Vc.tabulate_dof_coordinates(), corners, nc)] = f.x.array
    fine = prolongation(nc, nf, diagonal) @ grid_c
    row, col = np.divmod(np.arange((nf + 1) ** 2), nf + 1)
    for g in range(0, (nf + 1) ** 2, 7):  # the coarse P1 function evaluated by dolfinx
        assert fine[g] == pytest.approx(point_value(f, [col[g] / nf, row[g] / nf])[0], abs=1e-13)


def test_prolongation_refuses_non_nested():
    with pytest.raises(ValueError, match="nest"):
        prolongation(5, 16, "right")
    with pytest.raises(ValueError, match="diagonal"):
        prolongation(4, 16, "crossed")


def test_rates_near_one(tmp_path):
    """Spatial error at k = k_ref and temporal error at n = n_ref both fall at first order."""
    cfg = ROOT / "configs/example1.toml"
    rows_h, _ = study(cfg, [8, 16], [0.005], 32, 0.005, tmp_path, log=lambda *_: None)
    rows_k, _ = study(cfg, [32], [0.1, 0.05, 0.025], 32, 0.005, tmp_path, log=lambda *_: None)
    rh = rates(rows_h)["h"]["0.005"]
    rk = rates(rows_k)["k"]["32"]
    assert 0.8 <= rh <= 1.3, rh
    assert 0.8 <= rk <= 1.4, rk
    assert all(r["error"] > 0 for r in rows_h + rows_k)
    assert paper_error(128, 0.001) == 8.289e-4 and paper_error(5, 0.1) is None
