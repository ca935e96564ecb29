"""Semismooth Newton globalized on the level's energy from the first iteration (``solver.method =
"newton_energy"``; docs/model.md §4).

Where the level's F = 0 is the minimum of the convex energy (contact without the implicit memory term,
:func:`~damped_newton.has_energy`)

    E(u) = 1/2 u.K u - b.u + int P(u_nu - g) ds,      P' = p (the compliance law),

every iterate is a Newton step d = -J(x)^{-1} F(x) (J = K + C(active set of x), the same step as plain
Newton's) followed by one of:

- the full step, where its end keeps the active set of its start: it lies on one quadratic piece of E and is
  exact (so on a level where the zone stays put this is plain Newton, step for step);
- the full step, where its end has an active set not met before on this level, on the level's first
  FREE_STEPS iterations (a zone that closes from nothing would otherwise grow by a point or two per damped
  step) and later where it lowers ||F||;
- otherwise the minimum of E on the line x + lam d, lam in (0, 1] (damped_newton.line_minimum).

Full steps that change the active set go to distinct sets, so there are finitely many; between them E does not
grow. So the iterates cannot cycle: no watch and no fallback are needed. The stopping test is plain Newton's
(:class:`~newton.NewtonTest`, given the full Newton step |d|), so the level is solved to the same
tolerance. It requires an energy: without one (the implicit memory term) the registry builds plain Newton
instead (methods.py).
"""

from __future__ import annotations

from dolfinx.fem import petsc as fpetsc
from mpi4py import MPI
from petsc4py import PETSc

from solver.errors import ConfigError
from solver.physics.displacement import SolveInfo
from solver.solvers.damped_newton import DampedResult, along, has_energy, line_minimum
from solver.solvers.linear import REASONS_SNES
from solver.solvers.method import DisplacementMethod
from solver.solvers.newton import NewtonCore, NewtonTest, RetriesDirectly

FREE_STEPS = 2  # a level's first steps to a new active set are taken in full, whatever their residual


class EnergyNewtonSolver(RetriesDirectly, DisplacementMethod):
    """Each contact level solved by Newton steps with an exact line search on the energy (see the module
    docstring), on :class:`NewtonCore`'s KSP (options under ``mech_``) and to plain Newton's test with the scene's
    ``max_it``. Requires an energy (:func:`~damped_newton.has_energy`)."""

    starts_anywhere = True  # no prediction from the level's start

    def __init__(self, core: NewtonCore) -> None:
        problem = core.problem
        if not has_energy(problem):
            raise ConfigError(key="solver.method", value="newton_energy",
                              allowed="needs a contact energy (no implicit memory term): methods.py builds newton")
        self.core, self.problem = core, problem
        self.test = NewtonTest(core.settings.rtol, core.settings.max_it, core.cycles, problem.contact)
        self._vectors: list | None = None  # the iteration's four work vectors, made at its first level (auto's
        # take-over may never run: a run that never hands over does not hold them)
        self._stale = False  # J was modified at a trial point since the last linear solve
        self._seen: list[bytes] = []  # the active sets of the level's iterates
        self._at_trial = False  # x is the last trial point, where J and the active set were assembled
        self.damped_steps = 0  # steps shorter than the Newton step, over the run
        self.retry_direct = True  # a failed iterative linear solve: the level again, directly (solve)
        self._start: PETSc.Vec | None = None

    @property
    def _work(self) -> list:
        if self._vectors is None:
            self._vectors = [self.problem.u.vector.duplicate() for _ in range(4)]
        return self._vectors

    def _solve(self, scale: float) -> SolveInfo:
        core = self.core
        self.test.start_level(scale)
        ksp = core.ksp
        ksp.setOperators(self.problem.J, self.problem.J)
        core.krylov_tolerance.apply(ksp, scale)
        out = self.iterate(ksp)
        self.problem.u.x.scatter_forward()
        core.count_factorizations(out.factorizations)
        name = REASONS_SNES.get(out.reason, str(out.reason))
        return self.finish(out, name, scale)

    def finish(self, out: DampedResult, name: str, scale: float) -> SolveInfo:
        """The level's SolveInfo (or DisplacementSolveError), through :meth:`NewtonCore.outcome`."""
        return self.core.outcome(out.reason, name, out.history, out.iterations, scale, out.factorizations,
                                 out.krylov_iterations)

    def iterate(self, ksp: PETSc.KSP) -> DampedResult:
        """Newton steps with the exact line search from u (u ends holding the last iterate)."""
        R = PETSc.SNES.ConvergedReason
        problem, iterative, core = self.problem, self.core.iterative, self.core
        x, F, d, y = self._work  # x: the iterate (u itself is overwritten at every trial point)
        problem.u.vector.copy(x)
        fpetsc.set_bc(x, problem.bcs)  # the level's Dirichlet values: every step keeps them (d = 0 there)
        problem.evaluate(x, F)
        out = DampedResult(R.ITERATING, 0, [F.norm()])
        self._seen = []
        self._at_trial = False
        snorm = 0.0
        for it in range(self.test.max_it + 1):
            out.iterations = it
            out.reason = self.test(it, x.norm(), snorm, out.history[-1])
            if out.reason != R.ITERATING:
                break
            # after a full step J is already x's (assembled at the trial point): not assembled again
            changed = False if self._at_trial else problem.update_jacobian(x)
            self._seen.append(problem.contact.fingerprint())  # x's active set
            if changed or self._stale or core.factorizations + out.factorizations == 0:
                out.factorizations += 1  # J changed (or the run's first solve factors it)
            self._stale = False
            ksp.solve(F, d)
            d.scale(-1.0)
            out.krylov_iterations += ksp.getIterationNumber() if iterative else 0
            out.linear_reason = ksp.getConvergedReason()
            if out.linear_reason < 0:
                out.reason = R.DIVERGED_LINEAR_SOLVE
                break
            self._step(x, d, y, F, out.history[-1])
            snorm = d.norm()  # the full Newton step decides "converged by step size" (damped_newton.py)
            problem.evaluate(x, F)
            out.history.append(F.norm())
        else:
            out.reason = R.DIVERGED_MAX_IT
        problem.sync(x)
        return out

    def _step(self, x: PETSc.Vec, d: PETSc.Vec, y: PETSc.Vec, F: PETSc.Vec, fnorm: float) -> None:
        """x += lam d: the full step where it keeps the active set, or leads to an active set not met before
        on this level with a smaller residual; else lam minimizes E on the line."""
        problem = self.problem
        self._at_trial = False
        slope = F.dot(d)  # phi'(0) of phi(lam) = E(x + lam d); < 0: a descent direction
        along(y, 1.0, d, x, problem.bcs, self.core.iterative)
        changed = problem.update_jacobian(y)  # the active set at the full step (J kept if it is taken)
        self._stale = self._stale or changed
        if changed and slope < 0.0 and not self._full_step_fits(y, F, fnorm):
            lam = line_minimum(problem, x, d, y, F, slope, self.core.iterative)
            if lam < 1.0:
                self.damped_steps += 1
                x.axpy(lam, d)
                if self.core.iterative:
                    fpetsc.set_bc(x, problem.bcs)
                return
        y.copy(x)
        self._at_trial = True

    def _full_step_fits(self, y: PETSc.Vec, F: PETSc.Vec, fnorm: float) -> bool:
        """Whether the full step to y is taken though it changes the active set: y's set is new on this level
        (so full steps never cycle) and ||F(y)|| < ||F(x)||. Uses F as a work vector. Collective."""
        new = self.problem.contact.fingerprint() not in self._seen
        if not self.problem.contact.comm.allreduce(new, op=MPI.LOR):
            return False
        if len(self._seen) <= FREE_STEPS:
            return True
        self.problem.evaluate(y, F)
        return F.norm() < fnorm
