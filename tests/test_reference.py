"""The reference comparison: exact interpolation between nested meshes of any degree, and a zero self-error."""

import numpy as np
import pytest
from conftest import ROOT
from dolfinx import fem, mesh
from mpi4py import MPI

from solver.reference import FineReference, interpolation_matrix

pytestmark = pytest.mark.serial  # the reference is one process


@pytest.mark.parametrize("coarse_degree,fine_degree", [(1, 2), (2, 2), (1, 1)])
def test_interpolation_between_nested_meshes_is_exact(coarse_degree, fine_degree):
    coarse = mesh.create_unit_square(MPI.COMM_SELF, 4, 4)
    fine = mesh.create_unit_square(MPI.COMM_SELF, 12, 12)
    Vc = fem.FunctionSpace(coarse, ("CG", coarse_degree))
    Vf = fem.FunctionSpace(fine, ("CG", fine_degree))
    f = fem.Function(Vc)
    f.interpolate(lambda x: 1.0 + x[0] - 2.0 * x[1] + (0.5 * x[0] * x[1] if coarse_degree == 2 else 0.0))
    P = interpolation_matrix(Vc, Vf.tabulate_dof_coordinates()[:, :2])
    x = Vf.tabulate_dof_coordinates()
    want = 1.0 + x[:, 0] - 2.0 * x[:, 1] + (0.5 * x[:, 0] * x[:, 1] if coarse_degree == 2 else 0.0)
    assert np.allclose(P @ f.x.array, want, rtol=0, atol=1e-13)


def test_a_point_outside_is_refused():
    m = mesh.create_unit_square(MPI.COMM_SELF, 2, 2)
    with pytest.raises(ValueError, match="outside"):
        interpolation_matrix(fem.FunctionSpace(m, ("CG", 1)), np.array([[1.5, 0.5]]))


def test_the_reference_measures_itself_as_exact(tmp_path):
    sets = ["discretization.u_degree=2", "time.order=2", "time.T=0.1"]
    ref = FineReference(ROOT / "configs/example1.toml", sets, 4, 0.05, tmp_path, log=lambda *a: None)
    rec = ref.measure([], 4, 0.05)
    assert rec["error"] < 1e-13 and rec["levels_compared"] == 3 and rec["failure"] is None
    coarse = ref.measure(["discretization.u_degree=1"], 2, 0.1)  # a coarser run: compared where times coincide
    assert coarse["levels_compared"] == 2 and coarse["error"] > 1e-4
