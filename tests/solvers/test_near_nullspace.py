"""The iterative path's near-nullspace on the contact boundary (issue 30, Krylov iterations): the rigid motions
without their normal component on Gamma_C, where the contact penalty 1/mu holds u . n."""

import numpy as np
import pytest
from mpi4py import MPI

from solver.config import load
from solver.run.model import build_model
from studies import REPO


def _model(comm, n: int = 4):
    cfg = load(REPO / "configs" / "example1_3d.toml", [f"mesh.nx={n}", f"mesh.ny={n}", f"mesh.nz={n}", "time.T=0.02",
                                                       "output.xdmf=false", "solver.linear='iterative'"])
    return build_model(cfg, comm)


def test_contact_normals_are_the_bottom_normal_on_gamma_c_and_zero_elsewhere(comm):
    """mu = 1e-10: every node of Gamma_C holds u . n (the contact is stiff against K), its normal -z."""
    from solver.solvers.newton import contact_normals

    model = _model(comm)
    n = contact_normals(model.mech.problem)
    z = model.u.function_space.tabulate_dof_coordinates()[:, 2]
    bottom = np.isclose(z, 0.0)
    assert np.allclose(n[bottom], [0.0, 0.0, -1.0], atol=1e-12) and not n[~bottom].any()
    assert comm.allreduce(int(bottom.sum())) > 0


def test_near_nullspace_has_no_normal_component_on_gamma_c_and_keeps_the_rest(comm):
    """Every vector of the solver's near-nullspace is zero along the normal at Gamma_C's nodes; the six vectors are
    orthonormal, and the tangential motions (translations along x and y) are still in their span."""
    model = _model(comm)
    ksp = model.mech.solver.core.ksp
    J = ksp.getOperators()[0]
    basis = J.getNearNullSpace().getVecs()
    assert len(basis) == 6
    gram = np.array([[a.dot(b) for b in basis] for a in basis])
    assert np.allclose(gram, np.eye(6), atol=1e-12)
    z = model.u.function_space.tabulate_dof_coordinates()[:, 2]
    owned = model.u.function_space.dofmap.index_map.size_local
    bottom = np.flatnonzero(np.isclose(z[:owned], 0.0))
    for b in basis:
        assert np.abs(b.array_r.reshape(-1, 3)[bottom, 2]).max(initial=0.0) < 1e-14
    for axis in (0, 1):  # a tangential translation, normalized, lies in the span
        t = basis[0].duplicate()
        t.array_w.reshape(-1, 3)[:] = np.eye(3)[axis]
        t.normalize()
        projected = sum(t.dot(b) ** 2 for b in basis)
        assert projected == pytest.approx(1.0, abs=1e-12)


def test_without_the_contact_near_nullspace_the_rigid_motions_move_gamma_c_along_its_normal(comm):
    """contact_near_nullspace = False (a study's option, no global): the plain rigid motions, among them the
    translation along the normal of Gamma_C."""
    model = build_model(_model(comm).cfg, comm, contact_near_nullspace=False)
    assert not model.mech.settings.newton.contact_near_nullspace
    basis = model.mech.solver.core.ksp.getOperators()[0].getNearNullSpace().getVecs()
    z = model.u.function_space.tabulate_dof_coordinates()[:, 2]
    owned = model.u.function_space.dofmap.index_map.size_local
    bottom = np.flatnonzero(np.isclose(z[:owned], 0.0))
    normal = comm.allreduce(max(np.abs(b.array_r.reshape(-1, 3)[bottom, 2]).max(initial=0.0) for b in basis),
                            op=MPI.MAX)
    assert normal > 1e-3


@pytest.mark.serial
def test_stiff_contact_takes_fewer_krylov_iterations_with_the_contact_near_nullspace():
    """3-D Example 1 at n = 8 (2,187 dofs), mu = 1e-10: the default near-nullspace takes fewer Krylov iterations
    per solve over the steps than the plain rigid motions (the parent's), and the same contact force to 1e-7."""
    from studies import krylov_contact

    rigid = krylov_contact.run_case_apart(8, 1e-10, "rigid")  # own processes: run_case_apart says why
    default = krylov_contact.run_case_apart(8, 1e-10, "contact")
    assert default["steps"] < 0.8 * rigid["steps"], (default, rigid)
    assert default["contact_force"] == pytest.approx(rigid["contact_force"], rel=1e-7)


def test_soft_contact_keeps_the_rigid_motions(comm):
    """mu = 1e-3 (1/mu int phi ds 0.05 K's diagonal at n = 4): the contact does not hold u . n, no normal is taken out."""
    from solver.solvers.newton import contact_normals

    cfg = load(REPO / "configs" / "example1_3d.toml", ["mesh.nx=4", "mesh.ny=4", "mesh.nz=4", "time.T=0.02",
                                                       "output.xdmf=false", "solver.linear='iterative'",
                                                       "boundary.bottom.mu=0.001"])
    assert not contact_normals(build_model(cfg, comm).mech.problem).any()


def test_power_law_contact_keeps_the_rigid_motions(comm):
    """The power law has no fixed stiffness to compare with K's: its nodes keep the rigid motions (and the unused
    default mu = 1e-10 of its part is not read)."""
    import tomllib

    from solver.config import from_dict
    from solver.solvers.newton import contact_normals

    scene = tomllib.loads((REPO / "configs" / "example1_3d.toml").read_text())
    scene["mesh"].update(nx=4, ny=4, nz=4)
    scene["time"]["T"] = 0.02
    scene["solver"] = {"linear": "iterative"}
    bottom = scene["boundary"]["bottom"]
    del bottom["mu"]
    bottom.update(law="power", coefficient=1e3, exponent=2.0)
    assert not contact_normals(build_model(from_dict(scene), comm).mech.problem).any()
