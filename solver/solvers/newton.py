"""Semismooth Newton on a level's displacement problem, driven by PETSc SNES (docs/model.md §3.3, §4).

The contact term's generalized derivative is H(u_nu - g)/mu (UFL differentiates max_value to
it). The Jacobian is rebuilt only when the active set changes, and PETSc refactors a
matrix only when it was modified, so a step with an unchanged active set costs one
triangular solve pair (with ``solver.linear = "iterative"``, GAMG is likewise set up again only
then; see :func:`linear.iterative_options`). Without contact (and without an implicit memory term) the problem
is linear and SNES runs as a single KSP solve.
"""

from __future__ import annotations

import numpy as np
from dolfinx.fem import petsc as fpetsc
from mpi4py import MPI
from petsc4py import PETSc

from solver.config import SolverConfig
from solver.errors import DisplacementSolveError
from solver.physics.displacement import DisplacementProblem, SolveInfo
from solver.solvers.damped_newton import damped_newton
from solver.solvers.linear import (
    KSP_RTOL_FACTOR,
    REASONS_SNES,
    check_options,
    clear_options,
    linear_options,
    rigid_body_modes,
    set_options,
)

FALLBACK_IT_FACTOR = 8  # the damped fallback's iterations, in units of solver.max_it
CYCLE = "DIVERGED_ACTIVE_SET_CYCLE"  # the reason named when plain Newton revisits an active set


class NewtonSolver:
    """SNES (options prefix ``mech_``) on a :class:`DisplacementProblem`, with the project's convergence test:

    ||F|| <= rtol * scale, or ||du|| <= rtol ||u|| after a Newton step (with 1/mu ~ 1e10 the
    residual has a round-off floor ~ eps ||J|| ||u|| that can exceed rtol * scale; a correction
    below rtol ||u|| then means the active set is settled and the direct solve exact).

    With a piecewise-linear contact law (and no implicit memory term) the residual is affine on each
    active set, so a Newton iterate depends only on the active set of the iterate before it: an
    active set met again, other than the last one, means Newton cycles and would go on until max_it.
    The level stops there (reason ``DIVERGED_ACTIVE_SET_CYCLE``), and the damped fallback, where
    allowed, takes it over; on the hard scene of tests/test_damped_newton.py the failing level stops after
    9 of its 25 iterations (16 factorizations fewer).
    """

    prefix = "mech_"

    def __init__(self, problem: DisplacementProblem, settings: SolverConfig, comm: MPI.Comm) -> None:
        self.problem, self.settings = problem, settings
        self.factorizations = 0  # factorizations (direct) or preconditioner set-ups (iterative)
        self.krylov_iterations = 0  # summed over the run (iterative solves)
        self._scale = 1.0
        self._initial: PETSc.Vec | None = None  # the first residual of a solve, computed before SNES starts
        self._F0 = problem.r.duplicate()
        # contact without the implicit memory term has an energy: the damped fallback descends it (where the scene
        # allows), and with a piecewise-linear law an iterate depends only on the active set (class docstring), so
        # cycles are detected
        contact = problem.contact
        energy = contact is not None and problem.Fm is None
        self._can_fall_back = settings.newton_fallback and energy
        self._u0 = problem.u.vector.duplicate()  # the level's start, for the fallback
        self._watch_cycles = energy and contact.piecewise_linear
        self._seen: list[bytes] = []  # the active sets of this level's iterates, in order
        self._watching = False  # during plain Newton only (the damped fallback may revisit an active set)
        self._cycled = False
        self._fallback_krylov = 0
        self.fallbacks = 0  # levels solved by the damped fallback (:meth:`_fallback`)
        # iterative: CG + GAMG on J with the rigid motions as near-nullspace; each Newton correction starts
        # from zero (the level itself starts from u_{n-1}), and GAMG is set up again only when J changes
        defaults = linear_options(comm, settings.linear, problem.symmetric, settings.rtol, elasticity=True)
        self._project = settings.linear == "iterative"
        # the Krylov tolerances are set per level (solve) unless the scene sets them itself
        self._own_tolerance = not any(k.lstrip("-") in (f"{self.prefix}ksp_rtol", f"{self.prefix}ksp_atol")
                                      for k, _ in settings.petsc_options)
        if self._project:
            self._nullspace = rigid_body_modes(problem.u.function_space)
            problem.J.setNearNullSpace(self._nullspace)
        defaults.update({
            "snes_type": "newtonls" if problem.nonlinear else "ksponly",
            "snes_linesearch_type": "basic",
            # the penalty 1/mu makes the residual jump by ~1/mu when contact first activates:
            # not a divergence, so PETSc's residual-growth test is off (max_it still applies)
            "snes_divergence_tolerance": "-1",
        })
        check_options(comm, self.prefix, defaults, settings.petsc_options, snes=True)
        set_options(self.prefix, defaults, settings.petsc_options)
        snes = PETSc.SNES().create(comm)
        snes.setOptionsPrefix(self.prefix)
        snes.setFunction(self._residual, problem.r.duplicate())
        snes.setJacobian(self._jacobian, problem.J, problem.J)
        snes.setTolerances(rtol=settings.rtol, atol=0.0, stol=settings.rtol, max_it=settings.max_it)
        snes.setConvergenceTest(self._converged)
        snes.setConvergenceHistory(reset=True)
        snes.setFromOptions()
        self._defaults = defaults
        self._clear_options()
        self.snes = snes
        # a preconditioner reads the options of its parts (multigrid levels, coarse solver) only when it is set
        # up, at a solve: they are put back in the database around each solve (and removed after it)

    def _clear_options(self) -> None:
        """Remove this solver's options (defaults and the scene's ``mech_`` ones) from PETSc's database."""
        clear_options(self.prefix, self._defaults)
        clear_options("", [k.lstrip("-") for k, _ in self.settings.petsc_options
                           if k.lstrip("-").startswith(self.prefix)])

    def _residual(self, snes: PETSc.SNES, x: PETSc.Vec, F: PETSc.Vec) -> None:
        if self._initial is not None:  # the first evaluation, at u_{n-1}: already known
            self._initial.copy(F)
            self._initial = None
            return
        if self._project:
            # a Krylov step leaves the prescribed dofs off their values by its own error (~1e-17 after a step
            # of ~1e-2); the contact term couples them into free rows with 1/mu ~ 1e10, a residual of ~1e-7
            # the Jacobian (prescribed columns removed) cannot see, so Newton would stall there. A direct
            # solve puts them exactly; here the iterate is put on them before it is evaluated.
            fpetsc.set_bc(x, self.problem.bcs)
        self.problem.evaluate(x, F)

    def _jacobian(self, snes: PETSc.SNES, x: PETSc.Vec, J: PETSc.Mat, P: PETSc.Mat) -> None:
        if self.problem.update_jacobian(x):
            self.factorizations += 1
        elif self.factorizations == 0:  # the first solve factors the fixed K
            self.factorizations = 1
        if self._watching and not self._seen:  # the level's first iterate
            self._seen.append(self.problem.contact.fingerprint())

    def _cycling(self) -> bool:
        """Whether the current iterate's active set is one of this level's earlier iterates' but the last
        (collective: a set is met again when it is on every rank)."""
        key = self.problem.contact.active_set_at()
        again = key in self._seen[:-1]
        self._seen.append(key)
        return self.problem.contact.comm.allreduce(again, op=MPI.LAND)

    def _converged(self, snes: PETSc.SNES, it: int, norms: tuple[float, float, float]) -> int:
        xnorm, snorm, fnorm = norms
        rtol = self.settings.rtol
        R = PETSc.SNES.ConvergedReason
        if not np.isfinite(fnorm):
            return R.DIVERGED_FNORM_NAN
        if fnorm <= rtol * self._scale:
            return R.CONVERGED_FNORM_ABS
        if it > 0 and snorm <= rtol * xnorm:
            return R.CONVERGED_SNORM_RELATIVE
        if it >= self.settings.max_it:
            return R.DIVERGED_MAX_IT
        if self._watching and it > 0 and self._cycling():
            self._cycled = True
            return R.DIVERGED_INNER  # named CYCLE by solve()
        return R.ITERATING

    def _fallback(self, history: list[float], its: int) -> tuple[int, list[float], int]:
        """Plain Newton failed: solve the level again from its start by Newton with an exact line search on the energy
        (:mod:`damped_newton`), with FALLBACK_IT_FACTOR times the iterations. Returns the reason, the residual
        history (plain Newton's but its last, then the damped ones) and the iterations of both."""
        u = self.problem.u
        self._u0.copy(u.vector)
        u.x.scatter_forward()
        cap = FALLBACK_IT_FACTOR * self.settings.max_it

        def converged(it: int, xnorm: float, snorm: float, fnorm: float) -> int:  # the same test, with the cap
            reason = self._converged(self.snes, it, (xnorm, snorm, fnorm))
            R = PETSc.SNES.ConvergedReason
            return R.ITERATING if reason == R.DIVERGED_MAX_IT and it < cap else reason

        set_options(self.prefix, self._defaults, self.settings.petsc_options)
        try:
            out = damped_newton(self.problem, self.snes.getKSP(), u.vector, cap, converged, self._project)
        finally:
            self._clear_options()
        u.x.scatter_forward()
        self.factorizations += out.factorizations
        self._fallback_krylov = out.krylov_iterations
        if out.reason > 0:
            self.fallbacks += 1
        return out.reason, [*history[:-1], *out.history], its + out.iterations

    def solve(self, scale: float) -> SolveInfo:
        """Solve the level (u holds the previous level as initial guess); raise DisplacementSolveError."""
        problem, u = self.problem, self.problem.u
        self._scale = scale
        if self._project and self._own_tolerance:
            # the Krylov solve of a Newton step need not go below what the Newton test asks of F: stop at
            # 0.1 rtol * scale (F after the step equals the Krylov residual while the active set holds), or at
            # 0.1 rtol relative to the step's right-hand side, whichever is reached first
            ksp = self.snes.getKSP()
            ksp.setTolerances(rtol=KSP_RTOL_FACTOR * self.settings.rtol, atol=KSP_RTOL_FACTOR * self.settings.rtol * scale)
        problem.first_residual(self._F0)
        self._initial = self._F0
        f0 = self.factorizations
        set_options(self.prefix, self._defaults, self.settings.petsc_options)
        if self._can_fall_back:
            u.vector.copy(self._u0)
        self._fallback_krylov = 0
        self._seen.clear()
        self._watching, self._cycled = self._watch_cycles, False
        try:
            self.snes.solve(None, u.vector)
        finally:
            self._clear_options()
            self._watching = False
        self._initial = None
        u.x.scatter_forward()
        reason = self.snes.getConvergedReason()
        history, _ = self.snes.getConvergenceHistory()
        its = self.snes.getIterationNumber()
        if reason < 0 and self._can_fall_back:
            self._cycled = False  # the fallback's own reason names its outcome
            reason, history, its = self._fallback(list(history[:its + 1]), its)
        if problem.nonlinear:
            residual = float(history[its]) if len(history) > its else float("nan")
        else:
            problem.evaluate(u.vector, problem.r)
            residual = problem.r.norm()
        ksp_reason = self.snes.getKSP().getConvergedReason()
        krylov = (self.snes.getLinearSolveIterations() + self._fallback_krylov) if self._project else 0
        self.krylov_iterations += krylov
        tol = self.settings.rtol * scale
        ok = reason > 0 and ksp_reason >= 0 and np.isfinite(residual)
        if ok and not problem.nonlinear:
            # one exact (direct) solve of a linear problem: the residual must meet the tolerance
            ok = residual <= tol
        problem.carried = ok
        name = CYCLE if (self._cycled and reason < 0) else REASONS_SNES.get(reason, str(reason))
        if not ok:
            raise DisplacementSolveError("SNES", name, its, list(history), tol, linear_reason=ksp_reason)
        return SolveInfo(max(its, 1), self.factorizations - f0, residual, name, linear_solves=max(its, 1),
                         krylov_iterations=krylov)
