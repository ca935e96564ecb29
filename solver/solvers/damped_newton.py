"""Newton with an exact line search on the energy: the fallback for a level plain Newton did not solve
(docs/model.md §4).

Without the implicit memory term, F(u) = 0 of a level is the minimum of the convex energy

    E(u) = 1/2 u.K u - b.u + int P(u_nu - g) ds,      P' = p (the compliance law),

over the displacements with the level's Dirichlet values. The semismooth Newton step d = -J^{-1} F is a
descent direction of E (J = K + C is symmetric positive definite), and E is minimized along it: the root of
phi'(lam) = F(x + lam d).d, nondecreasing in lam, so only residuals are evaluated (E itself would be lost in
round-off: its parts are O(1/mu) larger than its decrease). Plain Newton can instead cycle between active
sets when 1/mu is large and the contact facets small; descent on a convex energy cannot. A full step whose
end has the same active set as its start lies on one quadratic piece of E and is exact: it is taken as is.
The step-size test of convergence is given the full Newton step |d|, never the damped lam |d|.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field

from dolfinx.fem import petsc as fpetsc
from petsc4py import PETSc

from solver.physics.displacement import DisplacementProblem

FALLBACK_IT_FACTOR = 8  # the damped fallback's iterations, in units of solver.max_it
LINE_RTOL = 1e-2  # the line search stops where |phi'| has dropped to this fraction of phi'(0)
LINE_ITERATIONS = 30


@dataclass
class DampedResult:
    """What the damped iteration did: its reason (a SNES reason code), iterations, residual history, and
    the Jacobian rebuilds (each a factorization of a direct solver)."""

    reason: int
    iterations: int
    history: list[float] = field(default_factory=list)
    factorizations: int = 0
    linear_reason: int = 0
    krylov_iterations: int = 0


def has_energy(problem: DisplacementProblem) -> bool:
    """Whether the level's F = 0 minimizes a convex energy: contact without the implicit memory term."""
    return problem.contact is not None and problem.split is not None


class DampedFallback:
    """The hand-off of a level plain Newton did not solve to :func:`damped_newton`, and whether it may happen.

    Allowed where the scene allows it (``solver.newton_fallback``) and the problem has an energy to descend
    (:func:`has_energy`). The level is solved again from its start with FALLBACK_IT_FACTOR times ``max_it``
    iterations.
    """

    def __init__(self, problem: DisplacementProblem, allowed: bool, max_it: int) -> None:
        self.problem = problem
        self.allowed = allowed and has_energy(problem)
        self.cap = FALLBACK_IT_FACTOR * max_it
        self._start = problem.u.vector.duplicate()  # the level's start
        self.levels = 0  # levels it solved
        self.krylov_iterations = 0  # the last level's

    def remember_start(self) -> None:
        """A new level begins from u: keep it (where the fallback is allowed)."""
        if self.allowed:
            self.problem.u.vector.copy(self._start)
        self.krylov_iterations = 0

    def take_over(self, ksp: PETSc.KSP, test: Callable[[int, float, float, float], int], history: list[float],
                  its: int, iterative: bool) -> tuple[int, list[float], int, int]:
        """Solve the level again from its start; ``test`` is plain Newton's convergence test (its max_it is
        raised to the cap). Returns the reason, the residual history (plain Newton's but its last, then the
        damped ones), the iterations of both and the damped iteration's factorizations."""
        u = self.problem.u
        self._start.copy(u.vector)
        u.x.scatter_forward()
        cap = self.cap

        def converged(it: int, xnorm: float, snorm: float, fnorm: float) -> int:  # the same test, with the cap
            reason = test(it, xnorm, snorm, fnorm)
            R = PETSc.SNES.ConvergedReason
            return R.ITERATING if reason == R.DIVERGED_MAX_IT and it < cap else reason

        out = damped_newton(self.problem, ksp, u.vector, cap, converged, iterative)
        u.x.scatter_forward()
        self.krylov_iterations = out.krylov_iterations
        if out.reason > 0:
            self.levels += 1
        return out.reason, [*history[:-1], *out.history], its + out.iterations, out.factorizations


def damped_newton(problem: DisplacementProblem, ksp: PETSc.KSP, start: PETSc.Vec, max_it: int,
                  converged: Callable[[int, float, float, float], int], iterative: bool) -> DampedResult:
    """Solve F(x) = 0 from ``start`` (u's vector: it ends holding the last iterate) by Newton steps damped on
    the energy.

    ``converged(it, xnorm, snorm, fnorm)`` is the SNES convergence test (a ConvergedReason); ``iterative``:
    the linear solver is iterative, so the Dirichlet values are put on every iterate (it leaves them off by its
    error).
    Collective. Only for problems with an energy: contact without the implicit memory term."""
    x = start.copy()  # the iterate; u itself is overwritten by every evaluation at a trial point
    F, d, y = (x.duplicate() for _ in range(3))
    try:
        return _iterate(problem, ksp, x, max_it, converged, iterative, F, d, y)
    finally:
        x.copy(start)
        for v in (x, F, d, y):
            v.destroy()


def along(y: PETSc.Vec, lam: float, d: PETSc.Vec, x: PETSc.Vec, bcs, iterative: bool) -> None:
    """y = x + lam d, put on the Dirichlet values where an iterative solve leaves them off."""
    y.waxpy(lam, d, x)
    if iterative:
        fpetsc.set_bc(y, bcs)


def line_minimum(problem: DisplacementProblem, x: PETSc.Vec, d: PETSc.Vec, y: PETSc.Vec, F: PETSc.Vec,
                 slope: float, iterative: bool) -> float:
    """The step length in (0, 1] that minimizes E(x + lam d): the root of phi'(lam) = F(x + lam d).d, which is
    nondecreasing (E is convex) and piecewise smooth; found by the Illinois variant of regula falsi. Uses y
    and F as work vectors."""
    def dphi(lam: float) -> float:
        along(y, lam, d, x, problem.bcs, iterative)
        problem.evaluate(y, F)
        return F.dot(d)

    return illinois_root(dphi, slope)


def illinois_root(dphi: Callable[[float], float], slope: float) -> float:
    """lam in (0, 1] where a convex phi is least along a descent direction (slope = phi'(0) < 0): the root of phi'
    by the Illinois regula falsi, to LINE_RTOL of the slope; 1 where phi' stays negative up to the full step. The
    line search of the damped fallback, of newton_energy and of newton_condensed's reduced iteration."""
    lo, flo, hi = 0.0, slope, 1.0
    fhi = dphi(hi)
    if fhi <= 0.0:  # E decreases all the way: the full step
        return 1.0
    side, lam = 0, 1.0
    for _ in range(LINE_ITERATIONS):
        lam = (lo * fhi - hi * flo) / (fhi - flo)
        f = dphi(lam)
        if abs(f) <= LINE_RTOL * abs(slope):
            return lam
        if f < 0.0:
            lo, flo = lam, f
            if side == -1:
                fhi *= 0.5
            side = -1
        else:
            hi, fhi = lam, f
            if side == 1:
                flo *= 0.5
            side = 1
    return lo if lo > 0.0 else lam


def _iterate(problem, ksp, x, max_it, converged, iterative, F, d, y) -> DampedResult:
    R = PETSc.SNES.ConvergedReason
    contact, bcs = problem.contact, problem.bcs
    fpetsc.set_bc(x, bcs)  # the level's Dirichlet values: from here on every step keeps them (d = 0 there)
    contact.forget()
    problem.evaluate(x, F)
    out = DampedResult(R.ITERATING, 0, [F.norm()])
    snorm, stale = 0.0, True  # stale: J changed since the last linear solve
    for it in range(max_it + 1):
        out.iterations = it
        out.reason = converged(it, x.norm(), snorm, out.history[-1])
        if out.reason != R.ITERATING:
            return out
        if problem.update_jacobian(x) or stale:
            out.factorizations += 1
        ksp.solve(F, d)
        d.scale(-1.0)
        stale = False
        out.krylov_iterations += ksp.getIterationNumber() if iterative else 0
        out.linear_reason = ksp.getConvergedReason()
        if out.linear_reason < 0:
            out.reason = R.DIVERGED_LINEAR_SOLVE
            return out
        slope = F.dot(d)  # phi'(0) for phi(lam) = E(x + lam d); < 0 for a descent direction
        along(y, 1.0, d, x, bcs, iterative)
        lam = 1.0
        changed = problem.update_jacobian(y)  # J at the full step (kept if the full step is taken)
        stale = stale or changed
        if changed and slope < 0.0:  # the active set changes along d: minimize E on the line
            lam = line_minimum(problem, x, d, y, F, slope, iterative)
            if lam < 1.0:
                contact.forget()  # J was assembled at the full step: rebuild it at the new iterate
            along(y, lam, d, x, bcs, iterative)
        y.copy(x)
        # the convergence test gets the Newton step, not the damped one: a line search that stops a step at a
        # kink of E near its start (lam ~ 1e-6 with 1/mu ~ 1e10) moves x by less than rtol |x| while F is far
        # from 0, and "the step is below rtol |x|" must not read that as converged
        snorm = d.norm()
        problem.evaluate(x, F)
        out.history.append(F.norm())
    out.reason = R.DIVERGED_MAX_IT
    return out
