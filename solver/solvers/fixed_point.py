"""Contact methods that iterate on the contact forces with one matrix factored once (docs/model.md §4).

- :class:`FixedPointSolver`: K u+ = b - N^T W p(N u - g), the plain fixed point (any law).
- :class:`PenaltyDualitySolver`: Bermudez-Moreno. With omega = value/mu per point,
  (K + omega N^T W N) u+ = b + N^T W (omega g - q), and q+ the Yosida approximation of
  G - omega I at (r + lambda q), lambda = 1/(2 omega). Laws: linear and limited penetration
  (omega from the layer's mu); not power (refused by the scene check: p' is unbounded).

Both work on the contact term at its quadrature points (:class:`contact_points.ContactPoints`),
which is the UFL term exactly, and only the residual decides: a small step proves nothing
for a slowly contracting iteration. Failures are named: diverged (residual up 1e8-fold or
not finite), stagnated (no 0.1 % progress over 20 iterations), too many iterations.
"""

from __future__ import annotations

import numpy as np
import ufl
from dolfinx import fem
from dolfinx.fem import petsc as fpetsc
from mpi4py import MPI
from petsc4py import PETSc

from solver.config import BoundaryConfig
from solver.errors import DisplacementSolveError
from solver.mesh.geometry import Geometry
from solver.physics.contact import contact_ds
from solver.physics.contact_points import ContactPoints
from solver.physics.displacement import DisplacementProblem, SolveInfo
from solver.physics.operators import assemble_without_diagonal
from solver.solvers.linear import make_ksp
from solver.solvers.method import DisplacementMethod
from solver.solvers.settings import LinearSettings, PointIterationSettings


class ContactIteration(DisplacementMethod):
    """The loop both methods share: forces at the points -> right-hand side -> one factored solve -> residual."""

    name = ""

    def __init__(self, problem: DisplacementProblem, points: ContactPoints, settings: PointIterationSettings,
                 linear: LinearSettings, comm: MPI.Comm) -> None:
        self.problem, self.points, self.settings = problem, points, settings
        self.ksp = make_ksp(comm, self.matrix(), "mech_fp_",
                            linear.petsc_options, linear.kind)
        self._rhs = problem.r.duplicate()
        self._factored = False

    def matrix(self) -> PETSc.Mat:
        """The matrix factored once."""
        raise NotImplementedError

    def start(self, r: np.ndarray) -> None:
        """Set up the iteration's own state from u_nu - g at the initial guess."""

    def point_forces(self, r: np.ndarray) -> np.ndarray:
        """Values v at the points such that the right-hand side is b - N^T W v."""
        raise NotImplementedError

    def after_solve(self) -> None:
        """Update the iteration's own state from the new u."""

    def solve(self, scale: float) -> SolveInfo:
        """Iterate the level to ||F|| <= rtol * scale; raise DisplacementSolveError naming how it failed."""
        problem, pts, x, rhs = self.problem, self.points, self.problem.u.vector, self._rhs
        u = problem.u
        tol = self.settings.rtol * scale
        problem.evaluate(x, problem.r)
        history = [problem.r.norm()]
        self.start(pts.penetration(u.x.array))
        reason, it = ("CONVERGED_FNORM_ABS" if history[0] <= tol else None), 0
        linear_reason = 0
        while reason is None:
            it += 1
            with rhs.localForm() as v:  # N^T W values, assembled over ranks
                v.array[:] = pts.forces(self.point_forces(pts.penetration(u.x.array)))
            rhs.ghostUpdate(addv=PETSc.InsertMode.ADD, mode=PETSc.ScatterMode.REVERSE)
            rhs.aypx(-1.0, problem.b)
            fpetsc.set_bc(rhs, problem.bcs)
            self.ksp.solve(rhs, x)
            if self.ksp.getConvergedReason() < 0:
                linear_reason = self.ksp.getConvergedReason()
                reason = "DIVERGED_LINEAR_SOLVE"
                break
            u.x.scatter_forward()
            self.after_solve()
            problem.evaluate(x, problem.r)
            fnorm = problem.r.norm()
            history.append(fnorm)
            if not np.isfinite(fnorm):
                reason = "DIVERGED_FNORM_NAN"
            elif fnorm <= tol:
                reason = "CONVERGED_FNORM_ABS"
            elif fnorm > 1e8 * max(history[0], tol):
                reason = "DIVERGED_RESIDUAL_GROWTH"
            elif it >= 21 and fnorm > 0.999 * min(history[-21:-1]):
                reason = "DIVERGED_STAGNATION"
            elif it >= self.settings.max_it:
                reason = "DIVERGED_MAX_IT"
        ok = reason.startswith("CONVERGED")
        problem.level_converged() if ok else problem.forget_level()
        if not ok:
            raise DisplacementSolveError(self.name, reason, it, history, tol, linear_reason=linear_reason)
        factorizations = 0 if self._factored or it == 0 else 1  # the matrix is factored at its first solve
        self._factored = self._factored or it > 0
        return SolveInfo(it, factorizations, history[-1], reason, linear_solves=it)


class FixedPointSolver(ContactIteration):
    """K u+ = b - N^T W p(N u - g)."""

    name = "fixed_point"

    def matrix(self) -> PETSc.Mat:
        return self.problem.ops.K

    def point_forces(self, r: np.ndarray) -> np.ndarray:
        return self.points.pressure(r)


class PenaltyDualitySolver(ContactIteration):
    """Bermudez-Moreno penalty-duality: omega per point = ``penalty_duality_omega`` / mu, lambda = 1 / (2 omega)."""

    name = "penalty_duality"

    def __init__(self, problem: DisplacementProblem, points: ContactPoints, settings: PointIterationSettings,
                 linear: LinearSettings, comm: MPI.Comm, geo: Geometry, parts: tuple[BoundaryConfig, ...]) -> None:
        self.geo, self.parts = geo, parts
        self.omega = settings.penalty_duality_omega * points.inv_mu
        self.lam = 1.0 / (2.0 * self.omega)
        self.q = np.zeros_like(self.omega)
        super().__init__(problem, points, settings, linear, comm)

    def matrix(self) -> PETSc.Mat:
        """K + omega N^T W N, assembled as the UFL penalty term on the contact facets."""
        ops, s = self.problem.ops, self.settings
        n = ufl.FacetNormal(self.geo.mesh)
        a_pen = fem.form(sum((s.penalty_duality_omega / p.contact_law.compliance) * ufl.dot(ops.du, n) * ufl.dot(ops.w, n)
                             * contact_ds(self.geo, p, s.contact_rule)
                             for p in self.parts))
        P = fpetsc.create_matrix(a_pen)
        assemble_without_diagonal(P, a_pen, ops.bcs)
        A = ops.K.duplicate(copy=True)
        A.axpy(1.0, P, structure=PETSc.Mat.Structure.SUBSET_NONZERO_PATTERN)
        return A

    def start(self, r: np.ndarray) -> None:
        self.q = self.points.pressure(r) - self.omega * r  # (G - omega I)(r) at the start

    def point_forces(self, r: np.ndarray) -> np.ndarray:
        return self.q - self.omega * self.points.g

    def after_solve(self) -> None:
        """q+ = Yosida approximation of G - omega I at (r + lambda q), with lambda omega = 1/2.

        r solves y = (1 - lambda omega) r + lambda p(r): piecewise linear in r, inverted piece by piece by each
        point's law (:meth:`solver.laws.contact.PiecewiseLinearLaw.resolvent`).
        """
        y = self.points.penetration(self.problem.u.x.array) + self.lam * self.q
        r = self.points.laws.resolvent(y, self.lam, self.omega)
        self.q = (y - r) / self.lam
