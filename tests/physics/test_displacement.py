"""The displacement problem's fast paths: the Jacobian in the stiffness matrix's own storage (J = K + C(active set)
formed in K's matrix, K's rows under the contact Jacobian kept apart, F(u) still using K exactly), the split it
relies on, and the carried residual's contract. tests/physics/test_level.py checks F and J against the UFL
reference."""

from dolfinx.fem import petsc as fpetsc
from petsc4py import PETSc

from solver.config import from_dict
from solver.physics.operators import assemble_without_diagonal
from solver.run.model import build_model

SCENE = {"mesh": {"nx": 6, "ny": 6}, "memory": {"kernel": "none"}, "damage": {"enabled": False}}


def _fresh_K(model) -> PETSc.Mat:
    """K assembled again from its form, with the pattern of the problem's matrix (the definition)."""
    ops = model.mech.ops
    K = model.mech.problem.J.duplicate()
    K.zeroEntries()
    fpetsc.assemble_matrix(K, ops.bulk_form, ops.bcs)
    K.assemble()
    return K


def _press(model, reach: float) -> None:
    """Push the nodes left of x = reach 1e-3 down (into the foundation on the bottom: a new contact active set)."""
    x = model.u.function_space.tabulate_dof_coordinates()
    u = model.u.x.array.reshape(-1, 2)
    u[:] = 0.0
    u[:, 1] = -1e-3 * (x[:, 0] < reach)
    model.u.x.scatter_forward()


def test_jacobian_lives_in_the_stiffness_matrix_and_equals_k_plus_c(comm):
    """One stiffness-pattern matrix (J is K's storage); after two changes of the active set J is K + C of the last
    one exactly, and F(u) = K u + j(u) - b with the K of the definition."""
    model = build_model(from_dict(SCENE), comm)
    problem, contact = model.mech.problem, model.mech.contact
    assert problem.J.handle == problem.ops.K.handle
    problem.ops.assemble_rhs(0.0)
    K = _fresh_K(model)
    for reach in (0.5, 0.25):  # half the bottom pressed, then a quarter
        _press(model, reach)
        assert problem.update_jacobian(model.u.vector)
        C = contact.C.duplicate()
        C.zeroEntries()
        assemble_without_diagonal(C, contact.jacobian_form, problem.bcs)
        want = K.duplicate(copy=True)
        want.axpy(1.0, C, structure=PETSc.Mat.Structure.SUBSET_NONZERO_PATTERN)
        want.axpy(-1.0, problem.J)
        assert want.norm() == 0.0 and C.norm() > 0.0
    F, want = problem.r.duplicate(), problem.r.duplicate()
    problem.evaluate(model.u.vector, F)
    with want.localForm() as w:
        w.set(0.0)
    fpetsc.assemble_vector(want, contact.residual_form)
    want.ghostUpdate(addv=PETSc.InsertMode.ADD, mode=PETSc.ScatterMode.REVERSE)
    K.multAdd(model.u.vector, want, want)
    want.axpy(-1.0, problem.b)
    fpetsc.set_bc(want, problem.bcs, model.u.vector, -1.0)
    scale = want.norm()
    want.axpy(-1.0, F)
    assert want.norm() <= 1e-14 * scale and scale > 0


def test_the_implicit_memory_term_removes_the_split(comm):
    """With the implicit trapezoid term F_m the problem offers no split: J is a copy of K, no StiffnessRows."""
    model = build_model(from_dict({**SCENE, "memory": {"kernel": "constant", "rule": "trapezoid"},
                                   "solver": {"method": "newton"}}), comm)
    problem = model.mech.problem
    assert problem.split is None and problem.kept is None and problem.implicit_memory is not None
    assert problem.J.handle != problem.ops.K.handle and not problem.symmetric
    plain = build_model(from_dict(SCENE), comm).mech.problem
    assert plain.split is not None and plain.split.K.handle == plain.ops.K.handle
    assert plain.split.b.handle == plain.ops.b.handle and plain.split.contact is plain.contact


def test_the_carried_residual_is_the_problems_own_state(comm):
    """level_converged / forget_level set what ``carried`` reads; resume restores it and ||j|| from a checkpoint;
    without a carried level the first residual is a full evaluation, with one it is F_last + b_prev - b."""
    model = build_model(from_dict(SCENE), comm)
    problem = model.mech.problem
    assert not problem.carried
    problem.level_converged()
    assert problem.carried
    problem.forget_level()
    assert not problem.carried
    problem.resume(True, 2.5)
    assert problem.carried and problem.contact_norm == 2.5
    problem.F_last.set(1.0)  # a carried residual no evaluation could give: the first residual must come from it
    problem.ops.assemble_rhs(0.0)
    problem.ops.assemble_rhs(0.5)
    F = problem.r.duplicate()
    problem.first_residual(F)
    want = problem.ops.b_prev.copy()
    want.axpy(-1.0, problem.ops.b)
    want.shift(1.0)
    want.axpy(-1.0, F)
    assert want.norm() == 0.0
    problem.forget_level()
    problem.first_residual(F)
    evaluated = F.duplicate()
    problem.evaluate(model.u.vector, evaluated)
    evaluated.axpy(-1.0, F)
    assert evaluated.norm() == 0.0 and F.norm() > 0.0
