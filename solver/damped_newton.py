"""Newton with a backtracking line search on the energy: the fallback for a level plain Newton did not solve
(docs/model.md §3.3).

Without the implicit memory term, F(u) = 0 of a level is the minimum of the convex energy

    E(u) = 1/2 u.K u - b.u + int P(u_nu - g) ds,      P' = p (the compliance law),

over the displacements with the level's Dirichlet values. The semismooth Newton step d = -J^{-1} F is a
descent direction of E (J = K + C is symmetric positive definite), so backtracking until E decreases by a
fraction of the slope F.d (Armijo) converges from any start; plain Newton can instead cycle between active
sets when 1/mu is large and the contact facets small. A full step whose end has the same active set as its
start lies on one quadratic piece of E and minimizes E along d exactly: it is taken without the energy test
(near the solution that test is lost in round-off: E's parts are O(1/mu) larger than its decrease).
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field

from dolfinx.fem import petsc as fpetsc
from petsc4py import PETSc

from .displacement import DisplacementProblem

ARMIJO = 1e-4  # the fraction of the slope the energy must decrease by
MIN_STEP = 2.0**-30  # below this step length the line search gives up


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


def damped_newton(problem: DisplacementProblem, ksp: PETSc.KSP, start: PETSc.Vec, max_it: int,
                  converged: Callable[[int, float, float, float], int], project: bool) -> DampedResult:
    """Solve F(x) = 0 from ``start`` (u's vector: it ends holding the last iterate) by Newton steps damped on
    the energy.

    ``converged(it, xnorm, snorm, fnorm)`` is the SNES convergence test (a ConvergedReason); ``project``:
    put the Dirichlet values on every iterate (an iterative linear solver leaves them off by its error).
    Collective. Only for problems with an energy: contact without the implicit memory term."""
    x = start.copy()  # the iterate; u itself is overwritten by every evaluation at a trial point
    F, d, y, Kx, Kd = (x.duplicate() for _ in range(5))
    try:
        return _iterate(problem, ksp, x, max_it, converged, project, F, d, y, Kx, Kd)
    finally:
        x.copy(start)
        for v in (x, F, d, y, Kx, Kd):
            v.destroy()


def _iterate(problem, ksp, x, max_it, converged, project, F, d, y, Kx, Kd) -> DampedResult:
    R = PETSc.SNES.ConvergedReason
    contact, K, b, bcs = problem.contact, problem.ops.K, problem.ops.b, problem.bcs
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
        out.krylov_iterations += ksp.getIterationNumber() if project else 0
        out.linear_reason = ksp.getConvergedReason()
        if out.linear_reason < 0:
            out.reason = R.DIVERGED_LINEAR_SOLVE
            return out
        slope = F.dot(d)  # = dE/dlambda at 0, < 0 for a descent direction
        K.mult(x, Kx)
        K.mult(d, Kd)
        g1, q = d.dot(Kx) - d.dot(b), d.dot(Kd)
        lam = 1.0
        while True:
            y.waxpy(lam, d, x)
            if project:
                fpetsc.set_bc(y, bcs)
            changed = problem.update_jacobian(y)  # J at y, needed there if y is taken
            stale = stale or changed
            if not changed or slope >= 0.0:  # one quadratic piece (or round-off): the full step is exact
                break
            dE = lam * g1 + 0.5 * lam * lam * q + contact.energy_change(x, y)
            if dE <= ARMIJO * lam * slope:
                break
            contact.forget()  # J now belongs to a rejected point: rebuild it at the next iterate
            lam *= 0.5
            if lam < MIN_STEP:
                problem.evaluate(x, F)  # leave x and the carried residual consistent
                out.reason = R.DIVERGED_LINE_SEARCH
                return out
        y.copy(x)
        snorm = lam * d.norm()
        problem.evaluate(x, F)
        out.history.append(F.norm())
    out.reason = R.DIVERGED_MAX_IT
    return out
