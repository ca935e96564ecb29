"""Newton on the contact dofs alone (``solver.method = "newton_condensed"``; docs/model.md §4).

It relies on the problem's split (:class:`solver.physics.displacement.FixedSplit`, the level problem of
:mod:`solver.physics.level`): F(u) = K u + j(u) - b with K fixed for the run. The contact term j(u) of a level acts
only on the dofs of the contact facets (B, the Dirichlet ones left out: a Lagrange trace on a facet depends on the
facet's dofs only). Writing c = j_B(u) for the contact force on them, F(u) = 0 is

    u = u0 - K^{-1} P^T c,      u0 = K^{-1} b        (P: the restriction to B),

so with v = P u (the contact dofs' displacement) and S = P K^{-1} P^T (m x m, dense, SPD; built once from m
solves with K's factorization):

    H(v) = v - P u0 + S j_B(v) = 0,        and  F(u(v)) = P^T S^{-1} H(v)  exactly: ||F|| = ||S^{-1} H(v)||.

H is the gradient, times S, of the level's energy restricted to the displacements that are in equilibrium inside
(E(v) = 1/2 (v - P u0).S^{-1}(v - P u0) + int P(u_nu - g) ds), so the method of energy_newton.py applies to it
unchanged: the semismooth Newton step d = -(I + S C_BB)^{-1} H (C_BB: the contact Jacobian on B), taken in full
where the active set stays, or to a new active set early in the level or with a smaller residual, else the exact
line search on E along d (phi'(lam) = H(v + lam d).S^{-1} d). The same iterates, nearly, but each costs a
facet assembly and an m x m dense solve instead of a sparse factorization. A step that keeps v's active set (it
solves v's quadratic piece) is not taken on v: u is rebuilt from v by one solve with K (from u itself if no step was
taken) and the step taken in the full space, d_B = -(I + S C_BB)^{-1} P K^{-1} F, d = -K^{-1} (F + P^T C d_B)
elsewhere (two solves with K; d_B written as is, 1/mu amplifying its error), which also corrects the rebuild's
round-off on B (about 1e-6 in ||F||). Plain Newton's test decides, on the full F: the same equations to the same
tolerance. A level these full steps do not settle in POLISH_STEPS goes to energy_newton's iteration, with
factorizations of K + C.

In 2-D (linear and limited-penetration laws) the iteration on v runs on the contact term at its quadrature points
(:class:`~point_contact.PointContact`, :class:`PointReduced`): sparse products instead of facet assemblies, an exact line search
from the kinks of the piecewise-quadratic E, the active set looking ahead along the step after a damped one, and a
first set predicted from the last two levels (docs/model.md §4).

The parts: :mod:`contact_dofs` (B, C_BB), :mod:`condensation` (K's factorization, S, u0), :mod:`reduced` (the
iteration on v), :mod:`point_contact` (the contact term at its points on B) and :class:`CondensedNewtonSolver`
(a level: the iteration on v, the steps through K, energy_newton's iteration where they do not settle it).

It requires (:func:`applies`) a contact energy (no implicit memory term), a piecewise linear law, a direct linear
solver and at most MAX_CONTACT_DOFS contact dofs; elsewhere the registry builds newton_energy (methods.py).
"""

from __future__ import annotations

import numpy as np
import scipy.linalg as sla
from dolfinx.fem import petsc as fpetsc
from mpi4py import MPI
from petsc4py import PETSc

from solver.errors import ConfigError
from solver.physics.contact_points import ContactPoints
from solver.physics.displacement import DisplacementProblem, SolveInfo
from solver.physics.operators import assemble_without_diagonal
from solver.solvers.condensation import Condensation
from solver.solvers.contact_dofs import ContactDofs, contact_block
from solver.solvers.cycle_watch import CONVERGED_SET
from solver.solvers.damped_newton import DampedResult, has_energy
from solver.solvers.energy_newton import EnergyNewtonSolver
from solver.solvers.linear import REASONS_SNES
from solver.solvers.method import DisplacementMethod
from solver.solvers.point_contact import PointContact
from solver.solvers.reduced import PointReduced, Reduced
from solver.solvers.settings import LinearSettings

MAX_CONTACT_DOFS = 3000  # S is dense: m^2 doubles on every rank, m solves with K to build it
POLISH_STEPS = 3  # full Newton steps solved through K after the condensed iteration, before a factorization


def applies(problem: DisplacementProblem, linear: LinearSettings, m: int) -> bool:
    """Whether the condensation holds: an energy, a piecewise linear law, a direct solver, m small enough."""
    return (has_energy(problem) and problem.contact.piecewise_linear and not linear.iterative
            and 0 < m <= MAX_CONTACT_DOFS)


class CondensedNewtonSolver(DisplacementMethod):
    """The contact levels solved on the contact dofs first, then checked (and finished) in the full space by
    Newton steps through K, and by ``energy``'s iteration where those do not settle a level (module docstring).
    Requires :func:`applies`; ``points``: the contact term at its points (2-D), for :class:`PointReduced`."""

    def __init__(self, energy: EnergyNewtonSolver, dofs: ContactDofs, linear: LinearSettings,
                 points: ContactPoints | None = None) -> None:
        core = energy.core
        problem = core.problem
        if not applies(problem, linear, dofs.m):
            raise ConfigError(key="solver.method", value="newton_condensed",
                              allowed="does not apply here (condensed.applies): methods.py builds newton_energy")
        self.energy, self.core, self.problem, self.test = energy, core, problem, energy.test
        self.dofs, self.linear = dofs, linear
        # the contact term at its points on B (2-D): the reduced iteration of PointReduced; else Reduced's forms
        self.points = PointContact(points, dofs, problem.u) if PointContact.applies(points) else None
        self.has_path = self.points is not None  # PointReduced's compliance path on v
        self.cond: Condensation | None = None  # built at the first level (its m solves count in the time loop)
        self.reduced_iterations = 0  # over the run
        self.previous: np.ndarray | None = None  # the contact dofs' values at the last level's start
        self._level_time: float | None = None  # the time of the last level solved
        self.reduced_work = [problem.u.vector.duplicate() for _ in range(2)]

    def state(self) -> dict[str, np.ndarray]:
        """What a checkpoint carries besides u: the predictor's last level start on the contact dofs (owned dofs,
        NaN off them and before a first level), so that a restarted run predicts its first set as the
        uninterrupted one does."""
        if self.points is None:
            return {}
        out = np.full(self.problem.u.vector.getLocalSize(), np.nan)
        if self.previous is not None:
            out[self.dofs.local] = self.dofs.mine(self.previous)
        return {"predictor": out}

    def restore(self, name: str, values: np.ndarray) -> None:
        """Take back :meth:`state`'s ``name`` (owned values) from a checkpoint (collective)."""
        mine = np.asarray(values, dtype=float).ravel()[self.dofs.local]
        known = self.dofs.comm.allreduce(bool(np.isfinite(mine).all()), op=MPI.LAND)
        self.previous = self.dofs.gather(mine) if known else None

    def solve(self, scale: float) -> SolveInfo:
        """Solve the level on the contact dofs, rebuild u, check (and finish) it with the full iteration."""
        core = self.core
        if self.cond is None:
            self.cond = Condensation(self.problem, self.dofs, self.problem.u.function_space.mesh.comm, self.linear)
            core.count_factorizations(1)  # K's
            first = 1
        else:
            first = 0
        self.test.start_level(scale)
        if self.points is not None:
            # a level solved again (Heun's corrector, at the same time) starts next to its solution: no prediction,
            # and the predictor keeps the level's own start
            again = self._level_time is not None and self.problem.level_time == self._level_time
            reduced = PointReduced(self.cond, self.problem, self.reduced_work, core.settings, scale, self.points,
                                   None if again else self.previous)
            history, v, step = reduced.run()
            if not again:
                self.previous = reduced.start
            self._level_time = self.problem.level_time
        else:
            reduced = Reduced(self.cond, self.problem, self.reduced_work, core.settings, scale)
            history, v, step = reduced.run()
        its = len(history)
        self.reduced_iterations += its
        if its > 0:  # else the level starts from u itself, as energy_newton's would
            c = sla.cho_solve(self.cond.chol, self.cond.u0_B - v)
            self.cond.rebuild(c, self.problem.u.vector)
            self.problem.u.x.scatter_forward()
        piece = None
        if self.points is not None and reduced.state is not None:  # the piece the reduced iteration ended on,
            pc = self.points                                       # where it is not v's own active set
            r = pc.NB @ v + pc.c
            if not np.array_equal(reduced.state, pc.state(r)):
                piece = (pc.jacobian(reduced.state), pc.piece_force(r, reduced.state) - pc.force(r), reduced.state)
            # (on v's own set Newton's step at u is that piece's solution, with C assembled as the residual is:
            # C from the points differs from it by round-off, which 1/mu = 1e12 makes worth a second step)
        out = self._polish(history, step, piece)
        if out.reason < 0:  # not settled by Newton steps solved through K: energy_newton's full iteration
            ksp = core.ksp
            ksp.setOperators(self.problem.J, self.problem.J)
            full = self.energy.iterate(ksp)
            self.problem.u.x.scatter_forward()
            core.count_factorizations(full.factorizations)
            full.iterations += out.iterations
            full.history = [*out.history[:-1], *full.history]  # its first is out's last
            out = full
        out.factorizations += first  # K's, once per run
        name = REASONS_SNES.get(out.reason, str(out.reason))
        return self.energy.finish(out, name, scale)

    def _kept(self, u: PETSc.Vec, solved) -> bool:
        """Whether u, the end of a step through K, keeps the active set the step was solved on (``solved``: the
        step's set and piece): then u solves that set's linear equations, the level's to round-off."""
        key, step_piece = solved
        now = self._set_at(u, step_piece)
        same = now.shape == key.shape and bool(np.array_equal(now, key))
        return self.dofs.comm.allreduce(same, op=MPI.LAND)

    def _set_at(self, u: PETSc.Vec, piece) -> np.ndarray:
        """The active set at u in the form a step's ``piece`` names it: the points' states where the step solved
        a piece of the reduced iteration, else C_BB assembled at u (it depends on the set alone). Collective."""
        if piece is not None:
            pc = self.points
            return pc.state(pc.NB @ self.dofs.gather(u.array_r[self.dofs.local]) + pc.c)
        contact = self.problem.contact
        self.problem.sync(u)
        assemble_without_diagonal(contact.C, contact.jacobian_form, contact.bcs)
        return contact_block(contact.C, self.dofs, u.getOwnershipRange()[0])

    def _step_through_k(self, u: PETSc.Vec, F: PETSc.Vec, d: PETSc.Vec,
                        piece=None) -> tuple[float, np.ndarray]:
        """u += d, the full Newton step -J(u)^{-1} F(u) solved through K: d_B = -(I + S C)^{-1} P K^{-1} F on
        the contact dofs, d = -K^{-1} (F + P^T C d_B) elsewhere. Returns |d| and the active set the step solved
        (:meth:`_set_at`'s form). Two solves with K. ``piece``: (C_BB,
        dj_B, the points' states) of the quadratic piece the reduced iteration ended on, the step then solving that
        piece (F + P^T dj_B is its residual); default: Newton's step, C assembled at u."""
        problem, dofs, cond = self.problem, self.dofs, self.cond
        if piece is not None:
            C, dj, key = piece
            F.array[dofs.local] += dofs.mine(dj)
        else:
            assemble_without_diagonal(problem.contact.C, problem.contact.jacobian_form, problem.contact.bcs)
            C = contact_block(problem.contact.C, dofs, u.getOwnershipRange()[0])
            key = C
        cond.ksp.solve(F, d)  # K^{-1} F
        dB = -np.linalg.solve(np.eye(dofs.m) + cond.S @ C, dofs.gather(d.array_r[dofs.local]))
        d.scale(-1.0)
        cond.add_column_solve(-(C @ dB), d)
        d.array[dofs.local] = dofs.mine(dB)  # d_B itself (the contact term amplifies its error by 1/mu)
        fpetsc.set_bc(d, problem.bcs, scale=0.0)
        u.axpy(1.0, d)
        return d.norm(), key

    def _polish(self, history: list[float], step: float, piece=None) -> DampedResult:
        """Full Newton steps from the rebuilt u, each solved through K (:meth:`_step_through_k`, no
        factorization), under plain Newton's test; at most POLISH_STEPS of them, taken in full (u is within
        round-off of the level's solution). ``history``: ||F|| before each iteration done on v (they are counted
        first); ``step``: the norm of the last Newton step on v (0 if none), which the first test is given like
        energy_newton's test after that step."""
        R = PETSc.SNES.ConvergedReason
        problem = self.problem
        u, F, d = problem.u.vector, *self.reduced_work
        out = DampedResult(R.ITERATING, len(history), list(history))
        snorm, after, keep, keep_norm = step, int(step > 0.0), None, 0.0
        solved = None  # the active set the last step through K solved (None: no step yet)
        for it in range(POLISH_STEPS + 1):
            problem.evaluate(u, F)
            out.history.append(F.norm())
            if keep is not None and out.history[-1] >= out.history[-2]:  # the steps stopped helping: back to
                keep.copy(u)                                             # where v's step test had stopped
                out.history[-1], out.reason = keep_norm, R.CONVERGED_SNORM_RELATIVE
                break
            out.reason = self.test(it + after, u.norm(), snorm, out.history[-1])
            if out.reason == R.CONVERGED_SNORM_RELATIVE and it == 0 and after:
                # stopped on v's step with F above the tolerance (near a kink of the energy): full steps are
                # tried, as energy_newton's next ones would be, while they lower ||F||
                keep, keep_norm = u.copy(), out.history[-1]
                out.reason = R.ITERATING
            if (out.reason == R.ITERATING and solved is not None and self.test.near_floor(out.history[-1])
                    and self._kept(u, solved)):
                out.reason = CONVERGED_SET
            if out.reason != R.ITERATING:
                break
            if it == POLISH_STEPS:
                out.reason = R.DIVERGED_MAX_IT
                if keep is not None:
                    keep.copy(u)
                    out.history[-1], out.reason = keep_norm, R.CONVERGED_SNORM_RELATIVE
                break
            out.iterations += 1
            step_piece = piece if it == 0 else None
            snorm, key = self._step_through_k(u, F, d, step_piece)
            solved = (key, step_piece)
        if keep is not None:
            keep.destroy()
        u.ghostUpdate(addv=PETSc.InsertMode.INSERT, mode=PETSc.ScatterMode.FORWARD)
        problem.u.x.scatter_forward()
        return out
