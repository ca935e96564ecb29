"""The fast evaluation of the level's problem (DisplacementProblem: the split F = K u + j(u) - b_n, J = K + C in K's
storage, the carried residual) equals the UFL reference F(u; w), J = dF/du of solver/physics/level.py assembled
directly: at random u on both sides of the contact, with and without the implicit memory term (its truncation
acting at some points), with and without contact, 2-D and 3-D.

Round-off bound (the error model). Each entry of F or J is, on either side, a floating-point sum of products; a sum
of m terms carries an error of at most gamma_m = m u / (1 - m u) times the sum of the terms' magnitudes (Higham,
Accuracy and Stability, §3.1), u the unit round-off. The two sides sum the same terms in different orders
(per-cell kernels and a product with the assembled K, against one kernel of the whole form), so they differ by at
most 2 gamma_m times that sum of magnitudes. The magnitudes are bounded row by row: the stiffness part by
(|K_full| 1)_i (||x||_inf + ||d||_inf) (|K_full| the entrywise absolute values, without Dirichlet rows replaced,
d = g_n - x on the Dirichlet dofs: the lifting is part of the sum; a row sum, not |K||x|, since an entry of K may be a
near-cancellation of cell contributions), the loads (the body force f0_n included, in the scenes without contact),
the contact term and the memory sum by the absolute values of their assembled vectors (the memory sum by
|B| |M_n|), the implicit term by (k/2) g(0) |B| L (|zeta Phi_L| <= L), the Jacobian by the row sums of |K_full|,
|J_ref| and |J|. m = MAX_TERMS_PER_ROW x (the largest number of nonzeros in a row of K): per column, the products
of the quadrature points of the cells the column's node shares with the row's, at most 8 here. The bound is an upper
bound, loose by the cancellations it ignores; a missing or mis-signed term, or a stale carried residual, exceeds it
by many orders of magnitude."""

import numpy as np
import pytest
import ufl
from dolfinx import fem
from dolfinx.fem import petsc as fpetsc
from mpi4py import MPI
from petsc4py import PETSc

from solver.config import from_dict
from solver.physics.level import LevelForms, declare_level
from solver.run.model import build_model

MAX_TERMS_PER_ROW = 8
LOAD_2D = [[0.0, -10.0, -10.0], [1.0, -20.0, 0.0]]  # a traction that changes between levels: b_n does too
LOAD_3D = [[0.0, -10.0, 0.0, -10.0], [1.0, -20.0, 5.0, 0.0]]
GRAVITY_2D = [[0.0, 0.0, -1.0], [1.0, 2.0, -3.0]]  # a body force f0(t) (the scenes without contact)
GRAVITY_3D = [[0.0, 0.0, 0.0, -1.0], [1.0, 2.0, 1.0, -3.0]]
CONTACT = {"role": "contact", "gap": 0.0, "mu": 1e-10}
# the top moves down, its x free: Dirichlet values that differ from zero and between levels (the lifting)
MOVING = [[0.0, 0.0], [1.0, -0.004]]
AMPLITUDE = 1e-3  # of the random u: strains ~ 4e-3, A eps ~ 0.5 against L = 0.3, so the truncation acts at some points
L = 0.3


def _scene(dim: int, contact: bool, implicit: bool) -> dict:
    boundary = {"left": {"role": "clamped"}, "right": {"role": "traction", "traction": LOAD_2D if dim == 2 else LOAD_3D}}
    moving_top = {"role": "displacement", "displacement": ["free"] * (dim - 1) + [MOVING]}
    boundary["bottom" if contact else "top"] = CONTACT if contact else moving_top
    if dim == 2:
        mesh, material = {"nx": 4, "ny": 4}, {"model": "plane_stress"}
    else:
        mesh = {"kind": "box", "corners": [[0.0, 0.0, 0.0], [1.0, 1.0, 1.0]], "nx": 2, "ny": 2, "nz": 2}
        material = {"model": "3d"}
    scene = {"body_force": {"f": GRAVITY_2D if dim == 2 else GRAVITY_3D}} if not contact else {}
    return {**scene, "mesh": mesh, "material": material, "boundary": boundary, "damage": {"enabled": False},
            "memory": {"kernel": "constant", "L": L, "rule": "trapezoid" if implicit else "left"},
            "time": {"T": 1.0, "k": 0.25}, "solver": {"method": "newton"}}


CASES = [(2, True, False), (2, True, True), (2, False, False), (2, False, True), (3, True, False), (3, True, True),
         (3, False, True)]
IDS = [f"{d}d-{'contact' if c else 'free'}-{'implicit' if i else 'left'}" for d, c, i in CASES]


def _level(comm, case) -> tuple:
    """The model of a case, its level forms, and a random memory M_n and implicit weight."""
    dim, contact, implicit = case
    cfg = from_dict(_scene(dim, contact, implicit))
    model = build_model(cfg, comm)
    problem = model.mech.problem
    parts = tuple(b for b in cfg.boundaries if b.role == "contact")
    forms = declare_level(model.geo, model.u, problem.ops, parts, cfg.solver.contact_quadrature_degree,
                          problem.implicit_memory)
    assert (forms.contact is not None) == contact and (forms.implicit_memory is not None) == implicit
    assert forms.fixed_stiffness == (problem.split is not None)
    if implicit:
        model.history.current_weight.value = 0.5 * 0.25  # (k/2) g(0), as the history's commit sets it from level 1
    _random_memory(model, comm, seed=1)
    return model, forms


def _random_memory(model, comm, seed: int) -> None:
    M = model.history.M
    M.x.array[:] = np.random.default_rng(seed + 100 * comm.rank).standard_normal(M.x.array.size)
    M.x.scatter_forward()


def _random_u(model, comm, seed: int) -> PETSc.Vec:
    """u random on both sides of the contact (u_nu - g of either sign), with the Dirichlet values of b's time."""
    u = model.u
    u.x.array[:] = AMPLITUDE * np.random.default_rng(seed + 100 * comm.rank).uniform(-1.0, 1.0, u.x.array.size)
    u.x.scatter_forward()
    fpetsc.set_bc(u.vector, model.mech.problem.bcs)
    u.x.scatter_forward()
    return u.vector


def _vector(model, form) -> PETSc.Vec:
    v = model.mech.problem.r.duplicate()
    with v.localForm() as local:
        local.set(0.0)
    fpetsc.assemble_vector(v, fem.form(form))
    v.ghostUpdate(addv=PETSc.InsertMode.ADD, mode=PETSc.ScatterMode.REVERSE)
    return v


def _abs(A: PETSc.Mat) -> PETSc.Mat:
    """|A| entrywise."""
    B = A.duplicate(copy=True)
    start, end = B.getOwnershipRange()
    indptr, cols, vals = B.getValuesCSR()
    B.setValuesIJV(indptr, cols, np.abs(vals), rowmap=np.arange(start, end, dtype=PETSc.IntType))
    B.assemble()
    return B


def _row_sums(A: PETSc.Mat) -> np.ndarray:
    ones, out = A.createVecRight(), A.createVecLeft()
    ones.set(1.0)
    _abs(A).mult(ones, out)
    return out.array.copy()


def _matrix(form, bcs=()) -> PETSc.Mat:
    A = fpetsc.assemble_matrix(fem.form(form), list(bcs))
    A.assemble()
    return A


def _gamma(model) -> float:
    """2 gamma_m for this mesh's K (m = MAX_TERMS_PER_ROW x the most nonzeros in a row)."""
    indptr = model.mech.ops.K.getValuesCSR()[0]
    nnz = model.comm.allreduce(int(np.diff(indptr).max()), op=MPI.MAX)
    m = MAX_TERMS_PER_ROW * nnz
    u = np.finfo(float).eps / 2
    return 2 * m * u / (1 - m * u)


def _residual_bound(model, forms: LevelForms, x: PETSc.Vec) -> np.ndarray:
    """Row by row: 2 gamma_m times the bound of the magnitudes of F_i's terms (module docstring)."""
    ops = model.mech.ops
    K_full = _matrix(forms.stiffness)
    d = _lifting_shift(model, x)
    sizes = [float(np.abs(v.array_r).max(initial=0.0)) for v in (x, d.vector)]
    scale = _row_sums(K_full) * sum(model.comm.allreduce(v, op=MPI.MAX) for v in sizes)
    for term in (forms.loads, forms.contact):
        if term is not None:
            scale += np.abs(_vector(model, term).array)
    M = model.history.M
    B = _abs(_matrix(ufl.inner(ufl.TrialFunction(M.function_space), ufl.sym(ufl.grad(ops.w))) * model.history.rule.dx))
    m_abs, s = B.createVecRight(), B.createVecLeft()
    m_abs.array[:] = np.abs(M.vector.array_r)
    B.mult(m_abs, s)
    scale += s.array
    if forms.implicit_memory is not None:
        m_abs.set(float(model.history.current_weight.value) * L)
        B.mult(m_abs, s)
        scale += s.array
    return _gamma(model) * scale


def _lifting_shift(model, x: PETSc.Vec) -> fem.Function:
    """d = g_n - x on the Dirichlet dofs, 0 elsewhere."""
    d = fem.Function(model.u.function_space)
    d.x.array[:] = 0.0
    fpetsc.set_bc(d.vector, model.mech.problem.bcs, x, 1.0)
    d.x.scatter_forward()
    return d


def _reference_residual(model, forms: LevelForms, x: PETSc.Vec) -> PETSc.Vec:
    """F(x; w) assembled from the UFL reference, the Dirichlet values of t_n entering through the stiffness alone
    (the lifting: a(x + d, w), d = g_n - x on the Dirichlet dofs; the nonlinear terms at x), the Dirichlet rows
    x - g_n. Where x holds g_n (a Newton iterate) this is F(x; w) itself."""
    u = model.u
    x.copy(u.vector)
    u.x.scatter_forward()
    F = _vector(model, forms.residual)
    F.axpy(1.0, _vector(model, ufl.action(forms.stiffness, _lifting_shift(model, x))))
    fpetsc.set_bc(F, model.mech.problem.bcs, x, -1.0)
    return F


def _assert_close(got: PETSc.Vec, want: PETSc.Vec, bound: np.ndarray) -> None:
    err = np.abs(got.array_r - want.array_r)
    assert np.all(err <= bound), f"max error / bound {np.max(err / np.maximum(bound, 1e-300)):.3g}"


@pytest.mark.parametrize("case", CASES, ids=IDS)
def test_residual_and_first_residual_equal_the_ufl_reference(comm, case):
    """evaluate(x) = F(x) at two random x; after a converged level (level_converged), the next level's first
    residual, derived from the carried one where the split holds, = F(u_{n-1}) for b_n, with a new M_n, load and
    Dirichlet value, and (implicit term) a new F_m, which the carried residual could not know."""
    model, forms = _level(comm, case)
    problem = model.mech.problem
    problem.begin_level(0.25)
    F = problem.r.duplicate()
    for seed in (1, 2):
        x = _random_u(model, comm, seed)
        problem.evaluate(x, F)
        want = _reference_residual(model, forms, x)
        assert want.norm() > 0.0
        _assert_close(F, want, _residual_bound(model, forms, x))
    problem.level_converged()  # the level ends at x = u (seed 2)
    assert problem.carried
    _random_memory(model, comm, seed=3)
    if forms.implicit_memory is not None:  # F_m changes between levels (its weight, zeta_n): no carried residual
        model.history.current_weight.value = 0.3
    problem.begin_level(0.75)
    F0 = problem.r.duplicate()
    problem.first_residual(F0)
    x = model.u.vector
    want = _reference_residual(model, forms, x)
    bound = _residual_bound(model, forms, x)
    # the carried path adds F_{n-1} + b_{n-1} - b_n: two more roundings of those magnitudes
    bound += 2 * np.finfo(float).eps * (np.abs(problem.F_last.array_r) + np.abs(problem.ops.b_prev.array_r)
                                        + np.abs(problem.ops.b.array_r))
    _assert_close(F0, want, bound)
    problem.forget_level()
    assert not problem.carried


@pytest.mark.parametrize("case", CASES, ids=IDS)
def test_jacobian_and_stiffness_equal_the_ufl_reference(comm, case):
    """update_jacobian(x) brings J to dF/du at x (in K's storage, StiffnessRows, where the split holds), at two
    random x (two active sets); stiffness() is then K = a(du, w) with the Dirichlet rows as identity."""
    model, forms = _level(comm, case)
    problem = model.mech.problem
    problem.begin_level(0.25)
    bcs = problem.bcs
    K_full = _matrix(forms.stiffness)
    for seed in (1, 2):
        x = _random_u(model, comm, seed)
        problem.update_jacobian(x)
        want = _matrix(forms.jacobian, bcs)
        bound = _gamma(model) * (_row_sums(K_full) + _row_sums(want) + _row_sums(problem.J))
        _assert_matrix_close(problem.J, want, bound)
    K = problem.stiffness()
    want = _matrix(forms.stiffness, bcs)
    _assert_matrix_close(K, want, _gamma(model) * _row_sums(K_full))


def _assert_matrix_close(got: PETSc.Mat, want: PETSc.Mat, bound: np.ndarray) -> None:
    """Row i of got - want within bound_i, entry by entry."""
    D = got.duplicate(copy=True)
    D.axpy(-1.0, want, structure=PETSc.Mat.Structure.DIFFERENT_NONZERO_PATTERN)
    indptr, _, vals = D.getValuesCSR()
    rows = np.repeat(np.arange(len(indptr) - 1), np.diff(indptr))
    err = np.abs(vals)
    assert np.all(err <= bound[rows]), f"max error / bound {np.max(err / np.maximum(bound[rows], 1e-300)):.3g}"
    assert want.norm() > 0.0
