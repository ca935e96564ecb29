"""The fixed operators and the loads: clamped rows, the load vector of tractions, the memory term of b_n;
against closed forms, a block under gravity, a body-force table, a block squeezed between rollers by a
moving prescribed displacement (its reaction at every level), and the rigid-motion check."""

import numpy as np
import pytest
import ufl
from conftest import solve
from dolfinx import fem
from dolfinx.fem import petsc as fpetsc
from mpi4py import MPI
from petsc4py import PETSc

from solver.config import from_dict
from solver.errors import RigidMotionError
from solver.run.model import build_model

E, NU = 100.0, 0.3
ROLLER_X = {"role": "displacement", "displacement": [0.0, "free"]}  # a symmetry plane x = const
ROLLER_Y = {"role": "displacement", "displacement": ["free", 0.0]}
STATIC = {"memory": {"kernel": "none"}, "damage": {"enabled": False}}


def _model(comm, **sections):
    scene = {"mesh": {"nx": 4, "ny": 4}, "damage": {"enabled": False}, **sections}
    return build_model(from_dict(scene), comm)


def test_tractions_sum_to_the_load_on_free_dofs(comm):
    """Example 1's load (-10, -10) on the right side of length 1: nodal forces sum to it (no clamped node there)."""
    model = _model(comm, memory={"kernel": "none"})
    ops = model.mech.ops
    ops.assemble_rhs(0.0)
    n = model.u.function_space.dofmap.index_map.size_local
    b = ops.b.array[: 2 * n].reshape(-1, 2)
    total = comm.allreduce(b.sum(axis=0), op=MPI.SUM)
    assert total == pytest.approx([-10.0, -10.0], rel=1e-12)


def test_clamped_rows_are_identity_and_b_is_zero_there(comm):
    model = _model(comm, memory={"kernel": "none"})
    ops = model.mech.ops
    ops.assemble_rhs(0.0)
    dofs = ops.bcs[0].dof_indices()[0]
    owned = dofs[dofs < ops.K.getLocalSize()[0]]
    start = ops.K.getOwnershipRange()[0]
    for d in owned[:5]:
        cols, vals = ops.K.getRow(start + d)
        assert vals[list(cols).index(start + d)] == pytest.approx(1.0)
        assert np.count_nonzero(vals) == 1
    assert np.all(ops.b.array[owned] == 0.0)
    assert ops.K.isSymmetric(1e-12)


def test_memory_term_enters_b_as_minus_B_M(comm):
    model = _model(comm)
    ops = model.mech.ops
    ops.assemble_rhs(0.0)
    b0 = ops.b.copy()
    model.history.M.x.array[:] = 1.0  # a uniform memory stress
    ops.assemble_rhs(0.0)
    assert np.array_equal(ops.b_prev.array, b0.array)  # the previous b is kept
    # (M, eps(w)) for a uniform M is the boundary term int (M n) . w: summed over all nodes it is zero, so over
    # the free ones (the clamped rows of b are zero) it is minus the clamped side's -int_left M n = (1, 1)
    n = model.u.function_space.dofmap.index_map.size_local
    diff = (b0.array - ops.b.array)[: 2 * n]
    total = comm.allreduce(diff.reshape(-1, 2).sum(axis=0), op=MPI.SUM)
    assert total == pytest.approx([1.0, 1.0], rel=1e-12)


def _gravity_scene(n: int, f) -> dict:
    """Unit block, clamped bottom, rollers on both sides, plane strain, body force f (0, f_y) or a table."""
    return {**STATIC, "mesh": {"nx": n, "ny": n, "diagonal": "crossed"}, "material": {"E": E, "nu": NU, "model": "plane_strain"},
            "boundary": {"bottom": {"role": "clamped"}, "left": ROLLER_X, "right": ROLLER_X},
            "body_force": {"f": f}, "time": {"T": 1.0, "k": 0.5}}


def _column(fy: float):
    """u_y(y) of a column under f_y, fixed at y = 0, free at y = 1: (lambda + 2 mu) u_y'' = -f_y."""
    lam, mu = E * NU / ((1 + NU) * (1 - 2 * NU)), E / (2 * (1 + NU))
    return lambda y: fy * (y - y * y / 2) / (lam + 2 * mu)


@pytest.mark.parametrize("n", [2, 4])
def test_block_under_gravity(comm, n):
    """u = (0, f_y (y - y^2/2) / (lambda + 2 mu)): quadratic in y. With rollers on the sides the problem
    is a column; on the crossed mesh its P1 solution is exact at the nodes of the grid rows (the cell
    centres see the column's P1 solution, not the parabola). The clamp carries the weight."""
    fy = -2.0
    model, rows = solve(from_dict(_gravity_scene(n, [0.0, fy])), comm)
    x = model.u.function_space.tabulate_dof_coordinates()
    u = model.u.x.array.reshape(-1, 2)
    on_rows = np.isclose(np.round(x[:, 1] * n), x[:, 1] * n, atol=1e-9)
    exact = _column(fy)(x[:, 1])
    scale = abs(_column(fy)(1.0))
    assert comm.allreduce(float(np.abs(u[on_rows, 1] - exact[on_rows]).max(initial=0)), op=MPI.MAX) < 1e-12 * scale
    assert comm.allreduce(float(np.abs(u[:, 0]).max()), op=MPI.MAX) < 1e-14
    # centre nodes lie off the parabola (by ~h^2/10 of it): it is not P1, so the check above is not vacuous
    assert comm.allreduce(float(np.abs(u[~on_rows, 1] - exact[~on_rows]).max(initial=0)), op=MPI.MAX) > 1e-3 * scale / n**2
    assert rows[-1]["reaction_bottom_y"] == pytest.approx(-fy, rel=1e-12)  # the weight, pushed up by the clamp
    assert rows[-1]["reaction_left_x"] == pytest.approx(-rows[-1]["reaction_right_x"], rel=1e-12)


def test_body_force_table_is_linear_in_time(comm):
    """f_y(t) from a table [t, fx, fy]: at t = 0.5 half-way; u and the reaction follow it exactly."""
    model, rows = solve(from_dict(_gravity_scene(2, [[0.0, 0.0, 0.0], [1.0, 0.0, -4.0]])), comm)
    assert [r["reaction_bottom_y"] for r in rows] == pytest.approx([0.0, 2.0, 4.0], rel=1e-12, abs=1e-14)
    x = model.u.function_space.tabulate_dof_coordinates()
    top = np.isclose(x[:, 1], 1.0)
    u_top = model.u.x.array.reshape(-1, 2)[top, 1]
    assert np.allclose(u_top, _column(-4.0)(1.0), rtol=1e-12, atol=0)


def _squeezed(method: str, contact: bool) -> dict:
    """(0,2)x(0,1): rollers on the left (x) and the bottom (y), the top pushed down by delta t.
    An optional contact part on the right (gap 1: never touched) makes the problem nonlinear."""
    boundary = {"left": ROLLER_X, "bottom": ROLLER_Y,
                "top": {"role": "displacement", "displacement": ["free", [[0.0, 0.0], [1.0, -0.01]]]}}
    if contact:
        boundary["right"] = {"role": "contact", "gap": 1.0, "mu": 1e-2}
    return {**STATIC, "mesh": {"nx": 4, "ny": 3, "corners": [[0, 0], [2, 1]]}, "material": {"E": E, "nu": NU},
            "boundary": boundary, "time": {"T": 1.0, "k": 0.25}, "solver": {"method": method, "rtol": 1e-13, "max_it": 500}}


@pytest.mark.parametrize("method,contact", [("newton", False), ("newton", True), ("fixed_point", True),
                                            ("penalty_duality", True)])
def test_block_squeezed_between_rollers(comm, method, contact):
    """eps_yy = -delta t, eps_xx = -nu eps_yy (plane stress, free right side): uniform, exact in P1 at every
    level. The top roller's reaction is sigma_yy W = E eps_yy W, the bottom's its opposite, the left's 0.

    The prescribed value moves with t, so b_n carries K's lifting of it and each level's first residual
    (carried from the last) must see it: one solve per level proves it. Newton and the fixed point
    (contact inactive) solve exactly; penalty-duality iterates, here to rtol = 1e-13."""
    model = build_model(from_dict(_squeezed(method, contact)), comm)
    tol = 1e-12
    from solver.run.stepper import Stepper

    stepper = Stepper(model)
    x = model.u.function_space.tabulate_dof_coordinates()
    for n in range(5):
        row = stepper.step(n)
        t = row["t"]
        eyy = -0.01 * t
        exact = np.column_stack([-NU * eyy * x[:, 0], eyy * x[:, 1]]).ravel()
        err = comm.allreduce(float(np.abs(model.u.x.array - exact).max()), op=MPI.MAX)
        assert err <= tol * 0.01 * t, (n, err)
        assert row["reaction_top_y"] == pytest.approx(E * eyy * 2.0, rel=tol, abs=1e-14)
        assert row["reaction_bottom_y"] == pytest.approx(-E * eyy * 2.0, rel=tol, abs=1e-14)
        assert abs(row["reaction_left_x"]) <= tol * E * 0.01
        if n > 0 and method != "penalty_duality":
            assert row["newton_iterations"] == 1


def test_rotation_left_free_by_the_dirichlet_parts_is_named(comm):
    """u_x = 0 on the bottom and u_y = 0 on the left fix both directions (the scene check passes) but
    leave the rotation about the corner (0, 0) free: the build stops with a named reason."""
    cfg = from_dict({**STATIC, "mesh": {"nx": 2, "ny": 2},
                     "boundary": {"bottom": {"role": "displacement", "displacement": [0.0, "free"]},
                                  "left": {"role": "displacement", "displacement": ["free", 0.0]},
                                  "top": {"role": "traction", "traction": [0.0, -1.0]}}})
    with pytest.raises(RigidMotionError) as err:
        build_model(cfg, comm)
    assert err.value.motions == ["rotation about (0, 0)"] and err.value.kind == "singular"
    assert "\n" not in str(err.value)


@pytest.mark.parametrize("extra", [{}, {"discretization": {"u_degree": 2}, "time": {"order": 2}}], ids=["P1", "P2-order2"])
def test_memory_force_is_the_assembled_coupling(comm, extra):
    """B M through the strain operator (E^T W m) equals the assembled (M, eps(w)) to round-off, for a
    memory tensor that is not symmetric and differs on every point."""
    model = _model(comm, **extra)
    ops = model.mech.ops
    M = model.history.M
    M.x.array[:] = np.sin(np.arange(M.x.array.size) + 1000.0 * comm.rank)
    M.x.scatter_forward()
    # the definition: (S, eps(w)) for S in M's space, assembled, and the level's memory term (M, eps(w)) itself
    B = fpetsc.assemble_matrix(fem.form(ufl.inner(ufl.TrialFunction(M.function_space), ufl.sym(ufl.grad(ops.w)))
                                        * model.history.rule.dx))
    B.assemble()
    want, got, declared = ops.b.duplicate(), ops.b.duplicate(), ops.b.duplicate()
    B.mult(M.vector, want)
    with declared.localForm() as local:
        local.set(0.0)
    fpetsc.assemble_vector(declared, fem.form(ops.memory_ufl))
    declared.ghostUpdate(addv=PETSc.InsertMode.ADD, mode=PETSc.ScatterMode.REVERSE)
    declared.axpy(-1.0, want)
    assert declared.norm() <= 1e-13 * want.norm()
    ops._memory_force(M, got)
    got.axpy(-1.0, want)
    assert got.norm() <= 1e-13 * want.norm() and want.norm() > 0
