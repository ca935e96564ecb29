"""The reference comparison: exact interpolation between nested meshes of any degree, and a zero self-error."""

import numpy as np
import pytest
from conftest import ROOT
from dolfinx import fem, mesh
from mpi4py import MPI

from solver.mesh.transfer import interpolation_matrix
from studies.reference import FineReference

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


@pytest.mark.parametrize("ref_n", [4, 8, 16])
def test_pointwise_error_against_the_exact_one(ref_n):
    """A P1 run on n=4 judged against P2 on n=4 (same cells: the integrand is a polynomial, the rule exact) and on
    n=8 (nested: the reference's strain jumps inside a judged cell, which a rule only approximates -- the
    study's references are much finer than what they judge, so their kinks are small)."""
    import ufl
    from dolfinx.fem import petsc as fpetsc

    from solver.config import load
    from solver.mesh.transfer import petsc_to_scipy
    from solver.run.model import build_model
    from solver.run.stepper import Stepper
    from studies.reference import PointwiseError

    def level0(n, degree):
        cfg = load(ROOT / "configs/example1.toml", [f"mesh.nx={n}", f"mesh.ny={n}", "time.k=1.0", "output.xdmf=false",
                                                     f"discretization.u_degree={degree}"])
        model = build_model(cfg, MPI.COMM_SELF)
        Stepper(model).step(0)
        return model

    ref, run = level0(ref_n, 2), level0(4, 1)
    run.damage.zeta.x.array[:] = 0.7 + 0.1 * run.damage.zeta.function_space.tabulate_dof_coordinates()[:, 0]
    V, Z = ref.u.function_space, ref.damage.V
    # exact: interpolate the coarse fields onto the reference's dofs (nested), norms there
    P = interpolation_matrix(run.u.function_space, V.tabulate_dof_coordinates()[:, :2])
    du = ref.u.x.array - (P @ run.u.x.array.reshape(-1, 2)).ravel()
    w, v = ufl.TrialFunction(V), ufl.TestFunction(V)
    E = fpetsc.assemble_matrix(fem.form(ufl.inner(ufl.sym(ufl.grad(w)), ufl.sym(ufl.grad(v))) * ufl.dx))
    E.assemble()
    Pz = interpolation_matrix(run.damage.V, Z.tabulate_dof_coordinates()[:, :2])
    dz = ref.damage.zeta.x.array - Pz @ run.damage.zeta.x.array
    z, xi = ufl.TrialFunction(Z), ufl.TestFunction(Z)
    M = fpetsc.assemble_matrix(fem.form(z * xi * ufl.dx))
    M.assemble()
    exact_u = np.sqrt(du @ (petsc_to_scipy(E) @ du))
    exact_z = np.sqrt(dz @ (petsc_to_scipy(M) @ dz))
    assert exact_u > 1e-3 and exact_z > 1e-3
    eu, ez = PointwiseError(V, Z, run)(ref.u.x.array, ref.damage.zeta.x.array)
    if ref_n == 4:
        assert abs(eu - exact_u) < 1e-10 * exact_u and abs(ez - exact_z) < 1e-10 * exact_z
    else:  # the rule across the reference's kinks: measured 0.3 % (n = 8) and 0.55 % (n = 16) for u
        assert abs(eu - exact_u) < 0.01 * exact_u and abs(ez - exact_z) < 1e-3 * exact_z
    # a run judged against itself has no error
    assert PointwiseError(run.u.function_space, run.damage.V, run)(run.u.x.array, run.damage.zeta.x.array) \
        == pytest.approx((0.0, 0.0), abs=1e-13)
