"""PETSc solver options: the direct choices, scene options on top, nothing left behind."""

import numpy as np
from mpi4py import MPI
from petsc4py import PETSc

from solver.linear import REASONS_KSP, clear_options, direct_options, make_ksp, set_options


def test_direct_options_by_process_count():
    one = direct_options(MPI.COMM_SELF)
    assert one["pc_type"] == "cholesky" and one["pc_factor_mat_solver_type"] == "petsc"
    assert direct_options(MPI.COMM_SELF, symmetric=False)["pc_type"] == "lu"
    assert direct_options(MPI.COMM_SELF, "mumps")["pc_factor_mat_solver_type"] == "mumps"


def test_scene_options_override_defaults_and_are_cleared():
    set_options("t_", {"ksp_type": "preonly", "pc_type": "lu"}, (("t_pc_type", "jacobi"), ("other_x", "1")))
    opts = PETSc.Options()
    assert opts["t_ksp_type"] == "preonly" and opts["t_pc_type"] == "jacobi"
    assert not opts.hasName("other_x")  # another prefix's option is not ours to set
    clear_options("t_", ["ksp_type", "pc_type"])
    assert not opts.hasName("t_ksp_type") and not opts.hasName("t_pc_type")


def test_make_ksp_solves_a_small_spd_system():
    A = PETSc.Mat().createAIJ([3, 3], comm=MPI.COMM_SELF)
    A.setUp()
    for i, row in enumerate([[4.0, 1.0, 0.0], [1.0, 3.0, 1.0], [0.0, 1.0, 2.0]]):
        A.setValues(i, range(3), row)
    A.assemble()
    ksp = make_ksp(MPI.COMM_SELF, A, "lin_test_", ())
    b, x = A.createVecLeft(), A.createVecRight()
    b.array[:] = [1.0, 2.0, 3.0]
    ksp.solve(b, x)
    assert ksp.getConvergedReason() > 0 and REASONS_KSP[ksp.getConvergedReason()].startswith("CONVERGED")
    assert np.allclose(x.array, np.linalg.solve([[4, 1, 0], [1, 3, 1], [0, 1, 2]], [1, 2, 3]))
