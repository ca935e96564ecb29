"""PETSc options, factored direct solvers and preconditioned Krylov solvers shared by the physics modules.

Each solver has its own options prefix (``mech_`` for the displacement SNES
and its KSP, ``damage_`` for the damage KSP) so that a scene's
``[solver.petsc_options]`` can tune one without touching the other. Inside, each
solver object writes its options once under a prefix of its own (:class:`OwnOptions`).
"""

from __future__ import annotations

import itertools
import weakref
from contextlib import ExitStack

import numpy as np
from dolfinx import fem, la
from mpi4py import MPI
from petsc4py import PETSc

from solver.config.solver import NEWTON_METHODS
from solver.errors import ConfigError

# 3-D scenes: what ``auto`` picks (choose_linear). MUMPS's level 0 (two factorizations, K and K + C) is dearer
# than the iterative path's set-ups from about 10,000 dofs and its steps cheaper, with a break-even in steps that
# grows with the mesh, while its fill (time and memory) grows faster than the mesh: so MUMPS below
# AUTO_ITERATIVE_DOFS_3D dofs for a run of AUTO_DIRECT_MIN_STEPS_3D steps or more, the iterative path for shorter
# runs from AUTO_SHORT_RUN_DOFS_3D dofs and for every run from AUTO_ITERATIVE_DOFS_3D on. A run whose active set
# moves pays a factorization (MUMPS) or a set-up (iterative) at each change, so the rule counts only level 0's
# two. The measurements: docs/benchmarks/performance.md, "The linear solver auto".
AUTO_ITERATIVE_DOFS_3D = 60_000
AUTO_SHORT_RUN_DOFS_3D = 10_000
AUTO_DIRECT_MIN_STEPS_3D = 20
NEWTON = NEWTON_METHODS  # the methods that can solve iteratively (the others re-solve one factor)


def choose_linear(kind: str, comm: MPI.Comm, dim: int, dofs: int, method: str = "newton",
                  steps: int | None = None) -> str:
    """The linear solver ``solver.linear = kind`` stands for on a mesh of dimension ``dim`` with ``dofs``
    displacement dofs (global), for a run of ``steps`` steps (None: a long one): ``kind`` itself unless it is
    ``auto``.

    ``auto`` in 2-D: the sequential Cholesky on one process, solved redundantly on up to 4 ranks, MUMPS beyond
    (:func:`direct_options`). In 3-D (Newton only: the fixed-point methods re-solve one factored matrix many times,
    always MUMPS): MUMPS below ``AUTO_ITERATIVE_DOFS_3D`` dofs, except a run shorter than
    ``AUTO_DIRECT_MIN_STEPS_3D`` steps from ``AUTO_SHORT_RUN_DOFS_3D`` dofs on, and the iterative solver from
    ``AUTO_ITERATIVE_DOFS_3D`` on (the measurements above).
    """
    if kind != "auto":
        return kind
    if dim == 3:
        if method not in NEWTON:
            return "mumps"
        short = steps is not None and steps < AUTO_DIRECT_MIN_STEPS_3D
        return "iterative" if dofs >= AUTO_ITERATIVE_DOFS_3D or (short and dofs >= AUTO_SHORT_RUN_DOFS_3D) else "mumps"
    return _auto_direct(comm)


def has_cholmod() -> bool:
    """Whether this PETSc has SuiteSparse (CHOLMOD's Cholesky)."""
    return bool(PETSc.Sys.hasExternalPackage("suitesparse"))


def _auto_direct(comm: MPI.Comm) -> str:
    if comm.size == 1:
        return "cholmod" if has_cholmod() else "petsc"
    return "redundant" if comm.size <= 4 else "mumps"


def direct_options(comm: MPI.Comm, kind: str = "auto", symmetric: bool = True,
                   cholmod: bool = False) -> dict[str, str]:
    """A sparse Cholesky factorization of an SPD matrix, factored once and reused.

    ``petsc``: PETSc's sequential Cholesky with nested dissection (one process only);
    ``cholmod``: SuiteSparse's supernodal Cholesky (one process only; its factorization about 5 times faster than
    ``petsc``'s at 33,000 dofs, its triangular solves as fast), where ``cholmod`` is allowed (the displacement's
    J), the matrix symmetric and PETSc has SuiteSparse, else ``petsc``;
    ``redundant``: every rank holds the whole matrix and solves it with ``petsc``;
    ``mumps``: MUMPS's distributed Cholesky. ``auto`` picks ``cholmod`` (``petsc`` without SuiteSparse) on one
    process, ``redundant`` on up to 4 and ``mumps`` beyond: on a few ranks a MUMPS triangular solve costs more
    than the sequential one, so solving redundantly and sharing the rest of the work is faster
    (docs/benchmarks/performance.md).
    """
    if kind == "auto":
        kind = _auto_direct(comm)
    if kind == "cholmod" and not (cholmod and symmetric and has_cholmod()):
        kind = "petsc"
    if kind in ("petsc", "cholmod") and comm.size > 1:
        kind = "redundant"
    if kind == "cholmod":
        return {"ksp_type": "preonly", "pc_type": "cholesky", "pc_factor_mat_solver_type": "cholmod"}
    factor = "cholesky" if symmetric else "lu"
    seq = {"pc_type": factor, "pc_factor_mat_solver_type": "petsc", "pc_factor_mat_ordering_type": "nd"}
    if kind == "petsc":
        return {"ksp_type": "preonly", **seq}
    if kind == "redundant":
        opts = {"ksp_type": "preonly", "pc_type": "redundant", "pc_redundant_number": str(comm.size)}
        opts.update({f"redundant_{k}": v for k, v in seq.items()})
        return opts
    # MUMPS's workspace: its estimate + 50 % (ICNTL(14), default 20 %): at 20 % a factorization can fail with
    # INFOG(1) = -9, workspace too small (docs/benchmarks/performance.md, "MUMPS's workspace")
    return {"ksp_type": "preonly", "pc_type": factor, "pc_factor_mat_solver_type": "mumps", "mat_mumps_icntl_14": "50"}


# Krylov tolerances relative to the Newton tolerance rtol (see iterative_options)
KSP_RTOL_FACTOR = 0.1


class KrylovTolerance:
    """When and to what the Krylov solve of a Newton step is stopped, per level.

    It need not go below what the Newton test asks of F: stop at ``0.1 rtol * scale`` (F after the step equals
    the Krylov residual while the active set holds), or at ``0.1 rtol`` relative to the step's right-hand side,
    whichever is reached first. Only for an iterative solver, and not if the scene sets ``{prefix}ksp_rtol``
    or ``{prefix}ksp_atol`` itself."""

    def __init__(self, rtol: float, iterative: bool, prefix: str, user: tuple[tuple[str, str], ...]) -> None:
        self.rtol = rtol
        own = {f"{prefix}ksp_rtol", f"{prefix}ksp_atol"}
        self.applies = iterative and not any(k.lstrip("-") in own for k, _ in user)

    def tolerances(self, scale: float) -> dict[str, float]:
        """The KSP's rtol and atol for a level whose force scale is ``scale``."""
        return {"rtol": KSP_RTOL_FACTOR * self.rtol, "atol": KSP_RTOL_FACTOR * self.rtol * scale}

    def apply(self, ksp: PETSc.KSP, scale: float) -> None:
        """Set the level's tolerances on ``ksp`` (where the policy applies)."""
        if self.applies:
            ksp.setTolerances(**self.tolerances(scale))


# The displacement's AMG: GAMG's smoothed aggregation (PETSc's own), set up anew whenever J changes
# (pc_gamg_reuse_interpolation = false): an interpolation kept from the first set-up, K's before any contact, does
# not see the contact penalty 1/mu that J has from then on, and the Krylov iterations then grow with the penalty
# and the mesh. Trilinos ML stays one option away (solver.petsc_options.mech_pc_type = "ml"), with MIS aggregation
# among the defaults: its default (uncoupled) aggregation crashed in ML's allocator after some models built in one
# process (tests/solvers/test_ml_many_models.py). Measurements: docs/benchmarks/performance.md, "Krylov
# iterations and the contact stiffness".
SMOOTHER = {"mg_levels_ksp_type": "chebyshev", "mg_levels_pc_type": "jacobi", "mg_levels_esteig_ksp_type": "cg"}
ML_SAFE = {"pc_ml_CoarsenScheme": "MIS"}
AMG = {
    # the smoothers' Chebyshev bounds from their own CG estimate, not the smoothed aggregation's: with the latter
    # the preconditioner went indefinite on 3-D Example 1 at n = 14 with the plain rigid motions as near-nullspace
    "gamg": {"pc_type": "gamg", "pc_gamg_type": "agg", "pc_gamg_agg_nsmooths": "1",
             "pc_gamg_reuse_interpolation": "false", "pc_gamg_use_sa_esteig": "false", **SMOOTHER, **ML_SAFE},
    "ml": {"pc_type": "ml", **ML_SAFE, **SMOOTHER},
}
# Fischer's initial guess: each solve starts from the projection of its right-hand side on the last 10 solutions
# (reset when the matrix changes); the steps of a level sequence have slowly changing right-hand sides
GUESS = {"ksp_guess_type": "fischer", "ksp_guess_fischer_model": "1,10"}
DEFAULT_AMG = "gamg"  # GAMG's smoothed aggregation, set up anew when the matrix changes (AMG above)


def iterative_options(rtol: float, elasticity: bool, symmetric: bool = True, amg: str | None = None) -> dict[str, str]:
    """CG (GMRES if the matrix is not symmetric) with algebraic multigrid for the displacement (``elasticity``;
    ``amg`` = ``gamg`` or ``ml``, default :data:`DEFAULT_AMG`; the rigid-body near-nullspace comes from
    :func:`rigid_body_modes`) and Fischer's initial guess, or Jacobi for the damage's mass-plus-diffusion matrix,
    whose diagonal dominates.

    The Krylov tolerance is tied to the Newton tolerance ``rtol``: a linear solve stops when its true
    (unpreconditioned) residual is below ``0.1 rtol`` times its right-hand side (the Newton solver also stops
    it at ``0.1 rtol`` times the level's force scale, the Newton test's own tolerance). The Newton residual
    test (||F|| <= rtol * scale, evaluated with the exact F) still decides convergence; an inexact step can
    only cost an extra Newton iteration, not accuracy. The preconditioner is set up again only when PETSc sees
    the matrix modified (the Jacobian changes only with the contact active set), like a factorization.
    """
    opts = {"ksp_type": "cg" if symmetric else "gmres", "ksp_rtol": repr(KSP_RTOL_FACTOR * rtol),
            "ksp_atol": "0.0", "ksp_norm_type": "unpreconditioned", "ksp_max_it": "2000"}
    if not symmetric:
        opts["ksp_gmres_restart"] = "200"
    if elasticity:
        opts.update(AMG[amg or DEFAULT_AMG])
        if symmetric:  # Fischer's projection is in the energy norm of an SPD matrix
            opts.update(GUESS)
    else:
        opts["pc_type"] = "jacobi"
    return opts


def linear_options(comm: MPI.Comm, kind: str, symmetric: bool, rtol: float, elasticity: bool,
                   amg: str | None = None) -> dict[str, str]:
    """The options of ``solver.linear = kind``: a direct factorization, or ``iterative`` (``amg``: its AMG).
    CHOLMOD factors the displacement's J only (``elasticity``); the other matrices (damage) keep ``petsc``."""
    if kind == "iterative":
        return iterative_options(rtol, elasticity, symmetric, amg)
    return direct_options(comm, kind, symmetric, cholmod=elasticity)


def rigid_body_modes(V: fem.FunctionSpace, normals: np.ndarray | None = None) -> PETSc.NullSpace:
    """The rigid motions of a vector P-k space (3 in 2-D, 6 in 3-D), orthonormalized: GAMG's near-nullspace
    (built as in dolfinx's demo_elasticity.py).

    ``normals`` (nodes, d; unit rows on the contact boundary, zero elsewhere): the rigid motions' normal component
    is taken out at those nodes, v <- v - (v . n) n. The contact penalty 1/mu (1e10) makes u . n there nearly a
    constraint, and a rigid motion that moves Gamma_C along its normal is no near-nullspace vector of J: with it
    the Krylov iterations per solve grow with the mesh; without it they stay at the plain solve's
    (docs/benchmarks/performance.md)."""

    imap, bs = V.dofmap.index_map, V.dofmap.index_map_bs
    dim = V.mesh.geometry.dim
    nmodes = 3 if dim == 2 else 6
    basis = [la.create_petsc_vector(imap, bs) for _ in range(nmodes)]
    # one row per node, ghosts included (like the local form, whose dof k * bs + i is component i of node k): filled
    # node by node, without the cell-by-cell index arrays of the sub-spaces' dofmaps (their transients grow with
    # the cells)
    x = V.tabulate_dof_coordinates()
    with ExitStack() as stack:
        nodes = [np.asarray(stack.enter_context(b.localForm())).reshape(-1, bs) for b in basis]
        for i in range(dim):  # translations
            nodes[i][:, i] = 1.0
        rotations = ((0, 1),) if dim == 2 else ((0, 1), (1, 2), (2, 0))
        for v, (a, b) in zip(nodes[dim:], rotations):
            v[:, a] = -x[:, b]
            v[:, b] = x[:, a]
        if normals is not None:
            on = np.flatnonzero(np.any(normals != 0.0, axis=1))
            n = normals[on]
            for v in nodes:
                v[on] -= np.sum(v[on] * n, axis=1)[:, None] * n
    la.orthonormalize(basis)
    return PETSc.NullSpace().create(vectors=basis, comm=V.mesh.comm)


def set_options(prefix: str, defaults: dict[str, str], user: tuple[tuple[str, str], ...]) -> None:
    """Write defaults under ``prefix``, then the scene's own options (full names) on top."""
    opts = PETSc.Options()
    for key, value in defaults.items():
        opts[f"{prefix}{key}"] = value
    for key, value in user:
        if key.startswith(prefix):
            opts[key.lstrip("-")] = value


_INSTANCES = itertools.count()


class OwnOptions:
    """A solver object's options, written once into PETSc's database under a prefix of its own.

    The scene names options by the user-visible ``prefix`` (``mech_ksp_type``); they are written, with the
    defaults below them, as ``{prefix}{n}_ksp_type`` for the n-th object, whose SNES/KSP is given
    :attr:`prefix`. Two solvers in one process (tests, studies) then never read each other's options, and the
    options can stay in the database for the object's life: a preconditioner reads those of its parts
    (multigrid levels, a redundant or MUMPS factorization) at its set-up, during a solve. They are removed when
    ``owner`` is garbage-collected (or by :meth:`remove`)."""

    def __init__(self, owner: object, prefix: str, defaults: dict[str, str],
                 user: tuple[tuple[str, str], ...]) -> None:
        self.prefix = f"{prefix}{next(_INSTANCES)}_"
        opts = PETSc.Options()
        self.defaults = [f"{self.prefix}{key}" for key in defaults]
        self.user = [f"{self.prefix}{key.lstrip('-').removeprefix(prefix)}" for key, _ in user
                     if key.lstrip("-").startswith(prefix)]
        for name, value in zip(self.defaults, defaults.values()):
            opts[name] = value
        for name, value in zip(self.user, (v for k, v in user if k.lstrip("-").startswith(prefix))):
            opts[name] = value
        self._finalizer = weakref.finalize(owner, _delete, [*self.defaults, *self.user])

    def remove(self, defaults_only: bool = False) -> None:
        """Remove the options from the database (``defaults_only``: those the scene did not set; its own stay
        until the owner goes)."""
        if defaults_only:
            _delete([name for name in self.defaults if name not in self.user])
        else:
            self._finalizer()


def _delete(names: list[str]) -> None:
    opts = PETSc.Options()
    for name in names:
        if opts.hasName(name):
            opts.delValue(name)


def clear_options(prefix: str, keys) -> None:
    """Remove options written by :func:`set_options` (so runs in one process do not leak)."""
    opts = PETSc.Options()
    for key in keys:
        name = f"{prefix}{key}"
        if opts.hasName(name):
            opts.delValue(name)


def check_options(comm: MPI.Comm, prefix: str, defaults: dict[str, str], user: tuple[tuple[str, str], ...],
                  snes: bool = False) -> None:
    """Raise a ConfigError naming the scene's option under ``prefix`` that PETSc rejects (an unknown
    type, a value of the wrong kind, a factorization package that is not there).

    The options are tried on a small stand-in: a KSP (or SNES) with the same prefix on a diagonal
    matrix, set up so that the preconditioner's factorization is created. The culprit is found by
    trying the scene's options one at a time.
    """
    mine = tuple((k, v) for k, v in user if k.lstrip("-").startswith(prefix))
    if not mine:
        return
    reason = _probe(comm, prefix, defaults, mine, snes)
    if reason is None:
        return
    for key, value in mine:
        alone = _probe(comm, prefix, defaults, ((key, value),), snes)
        if alone is not None:
            raise ConfigError(key=f"solver.petsc_options.{key}", value=value, allowed=f"PETSc rejects it: {alone}")
    raise ConfigError(key="solver.petsc_options", value=dict(mine), allowed=f"PETSc rejects them together: {reason}")


def _probe(comm: MPI.Comm, prefix: str, defaults: dict[str, str], user: tuple[tuple[str, str], ...],
           snes: bool) -> str | None:
    """None if PETSc accepts the options on a stand-in problem, else the last line of its error."""
    set_options(prefix, defaults, user)
    A = PETSc.Mat().createAIJ(((1, None), (1, None)), nnz=(1, 0), comm=comm)
    start, _ = A.getOwnershipRange()
    A.setValue(start, start, 1.0)
    A.assemble()
    obj = ksp = None
    try:
        if snes:
            obj = PETSc.SNES().create(comm)
            obj.setOptionsPrefix(prefix)
            obj.setFromOptions()
            ksp = obj.getKSP()
        else:
            obj = ksp = PETSc.KSP().create(comm)
            ksp.setOptionsPrefix(prefix)
        ksp.setOperators(A)
        ksp.setFromOptions()
        ksp.setUp()
        return None
    except PETSc.Error as exc:
        lines = [ln.strip() for ln in str(exc).splitlines() if ln.strip()]
        return lines[-1].removeprefix("[0] ") if lines else f"error code {exc.ierr}"
    finally:
        if obj is not None:
            obj.destroy()
        A.destroy()
        clear_options(prefix, defaults)
        clear_options("", [k.lstrip("-") for k, _ in user])


def make_ksp(comm: MPI.Comm, A: PETSc.Mat, prefix: str, user: tuple[tuple[str, str], ...],
             kind: str = "auto", symmetric: bool = True, rtol: float = 1e-10) -> PETSc.KSP:
    """A KSP on a matrix; with the default options it factors once, and again only if A changes
    (``kind = 'iterative'``: Jacobi-preconditioned CG to ``0.1 rtol``, warm-started from the last solution).
    Options PETSc rejects raise a ConfigError first (:func:`check_options`)."""
    defaults = linear_options(comm, kind, symmetric, rtol, elasticity=False)
    check_options(comm, prefix, defaults, user)
    ksp = PETSc.KSP().create(comm)
    own = OwnOptions(ksp, prefix, defaults, user)
    ksp.setOptionsPrefix(own.prefix)
    ksp.setOperators(A)
    ksp.setFromOptions()
    if kind == "iterative":
        ksp.setInitialGuessNonzero(True)  # x holds the last solution: the previous level's field
    if defaults.get("pc_factor_mat_solver_type") == "mumps":
        ksp.setUp()  # MUMPS reads its mat_mumps_* options when it factors: factor while they are set
    # the defaults are removed before the first solve: a redundant factorization's inner solver, set up then,
    # takes PETSc's own defaults (the arithmetic the results are checked against)
    own.remove(defaults_only=True)
    return ksp


REASONS_KSP = {v: k for k, v in vars(PETSc.KSP.ConvergedReason).items() if isinstance(v, int)}
REASONS_SNES = {v: k for k, v in vars(PETSc.SNES.ConvergedReason).items() if isinstance(v, int)}
