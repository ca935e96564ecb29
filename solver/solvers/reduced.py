"""The iteration of newton_condensed on the contact dofs v = P u (docs/model.md §4).

With S = P K^{-1} P^T and u0 = K^{-1} b_n (condensation.py), a level's equations restricted to the displacements in
equilibrium inside are

    H(v) = v - P u0 + S j_B(v) = 0,        ||F(u(v))|| = ||S^{-1} H(v)||,

H being S times the gradient of the level's energy E(v) = 1/2 (v - P u0).S^{-1}(v - P u0) + int P(u_nu - g) ds.
Each step is the semismooth Newton step d = -(I + S C_BB)^{-1} H, taken in full where its end has an active set
not met before on the level and (after FREE_STEPS) a smaller residual, else to the minimum of E along d. A step
whose end keeps the active set solves that set's quadratic piece: the iteration stops there and the solver takes
the step through K in the full space (condensed.py).

:class:`Reduced` evaluates j_B and C_BB by facet assembly; :class:`PointReduced` (2-D) by sparse products at the
contact term's quadrature points, with the exact line search over the kinks of the piecewise quadratic E and a
first active set predicted from the last two levels: v + PREDICT (v - v_prev). A level that starts with no point in
contact (a first contact, or the return after a lift-off) takes continuation.py's compliance path on v first: the
contact term scaled to its stiffness ratios (RATIOS), STAGE_ITERATIONS steps each, then the level's own law.
"""

from __future__ import annotations

import numpy as np
import scipy.linalg as sla
from dolfinx.fem import petsc as fpetsc
from petsc4py import PETSc

from solver.physics.displacement import DisplacementProblem
from solver.physics.operators import assemble_without_diagonal
from solver.solvers.condensation import Condensation
from solver.solvers.contact_dofs import contact_block
from solver.solvers.continuation import RATIOS, STAGE_ITERATIONS, STIFF
from solver.solvers.damped_newton import illinois_root
from solver.solvers.energy_newton import FREE_STEPS
from solver.solvers.point_contact import PointContact
from solver.solvers.settings import NewtonSettings

# the first step's active set is the one at v + PREDICT (v - v_prev), v_prev the last level's start: half the last
# level's motion, measured best (docs/model.md §4)
PREDICT = 0.5


class Reduced:
    """One level's iteration on v = P u (module docstring): Newton steps, full or with the exact line search."""

    def __init__(self, cond: Condensation, problem: DisplacementProblem, work: list[PETSc.Vec],
                 settings: NewtonSettings, scale: float) -> None:
        self.cond, self.dofs, self.problem, self.settings = cond, cond.dofs, problem, settings
        self.x, self.F = work  # the full vector the forms read (u0 with v on B), and j there
        self.scale = scale
        # the active set whose quadratic piece the last step solved, where the iteration stopped on a step that
        # keeps it (PointReduced; None: v's own set)
        self.state: np.ndarray | None = None

    def evaluate(self, v: np.ndarray) -> tuple[np.ndarray, np.ndarray, bytes]:
        """H(v), C_BB(v) and the active set's fingerprint (C_BB's bytes). Collective."""
        problem, dofs, x = self.problem, self.dofs, self.x
        self.cond.u0.copy(x)
        x.array[dofs.local] = dofs.mine(v)
        problem.sync(x)
        contact = problem.contact
        with self.F.localForm() as f:
            f.set(0.0)
        fpetsc.assemble_vector(self.F, contact.residual_form)
        self.F.ghostUpdate(addv=PETSc.InsertMode.ADD, mode=PETSc.ScatterMode.REVERSE)
        jB = dofs.gather(self.F.array_r[dofs.local])
        assemble_without_diagonal(contact.C, contact.jacobian_form, contact.bcs)
        C = contact_block(contact.C, dofs, x.getOwnershipRange()[0])
        H = v - self.cond.u0_B + self.cond.S @ jB
        return H, C, C.tobytes()

    def step_test(self, v: np.ndarray, d: np.ndarray) -> bool:
        """NewtonTest's step test, on the full space: the full Newton step K^{-1} P^T S^{-1} d (d: its part on
        B) below rtol ||u(v)||, u(v) = u0 - K^{-1} P^T S^{-1} (P u0 - v). Two solves with K."""
        cond, x = self.cond, self.x
        x.set(0.0)
        cond.add_column_solve(sla.cho_solve(cond.chol, d), x)
        step = x.norm()
        cond.rebuild(sla.cho_solve(cond.chol, cond.u0_B - v), x)
        return step <= self.settings.rtol * x.norm()

    def fnorm(self, H: np.ndarray) -> float:
        """||F(u(v))|| = ||S^{-1} H||."""
        return float(np.linalg.norm(sla.cho_solve(self.cond.chol, H)))

    def run(self) -> tuple[list[float], np.ndarray, float]:
        """Iterate from the current u's contact dofs; returns ||F|| before each step taken (one per iteration),
        v (converged or not: the full iteration that follows decides) and the norm of the last step (0 if none)."""
        cond, settings = self.cond, self.settings
        cond.level()
        v = self.dofs.gather(self.problem.u.vector.array_r[self.dofs.local])
        H, C, key = self.evaluate(v)
        fnorm, seen, history = self.fnorm(H), [key], []
        snorm = 0.0
        unorm = max(self.problem.u.vector.norm(), 1e-300)
        for _ in range(settings.max_it * 8):
            if fnorm <= settings.rtol * self.scale:
                return history, v, snorm
            d = -np.linalg.solve(np.eye(len(v)) + cond.S @ C, H)
            y = v + d
            Hy, Cy, keyy = self.evaluate(y)
            if keyy == key:  # the step keeps v's active set: it solves v's quadratic piece, and is taken in the
                return history, v, snorm  # full space by _polish (from u itself on the level's first iteration)
            history.append(fnorm)
            lam = 1.0
            if keyy != key:
                fy = self.fnorm(Hy)
                full = keyy not in seen and (len(seen) <= FREE_STEPS or fy < fnorm)
                if not full:
                    lam = self._line_minimum(v, d, H)
            if lam < 1.0:
                v = v + lam * d
                H, C, key = self.evaluate(v)
            else:
                v, H, C, key = y, Hy, Cy, keyy
            seen.append(key)
            fnorm = self.fnorm(H)
            snorm = float(np.linalg.norm(d))  # B's part of the full step: the whole one only if this passes
            if snorm <= settings.rtol * unorm and self.step_test(v, d):
                return history, v, snorm
        return history, v, snorm

    def _line_minimum(self, v: np.ndarray, d: np.ndarray, H: np.ndarray) -> float:
        """lam in (0, 1] minimizing E(v + lam d): the root of phi'(lam) = H(v + lam d).S^{-1} d (Illinois)."""
        w = sla.cho_solve(self.cond.chol, d)

        def dphi(lam: float) -> float:
            return float(self.evaluate(v + lam * d)[0] @ w)

        slope = float(H @ w)
        if slope >= 0.0:
            return 1.0
        return illinois_root(dphi, slope)


class PointReduced(Reduced):
    """:class:`Reduced` with the contact term at its quadrature points (:class:`PointContact`), as an active-set
    iteration: each step solves the quadratic piece of the level's energy that an active set names (the contact
    law taken affine, p = r/mu, on its points), from the set predicted by the last two levels' contact dofs
    (linear extrapolation) at the level's first step and from the set the last step reached after that. A step
    whose end keeps its set has found the level's solution: _polish takes it through K. Otherwise the end is
    taken where it is new and lowers ||F|| (or on the level's first FREE_STEPS), else the exact minimum of the
    level's energy along the step (from the kinks) with the set just beyond it along the step (a point the line
    search stopped at, entering contact, is in it: the directional derivative). Every evaluation is a sparse
    product on the m contact dofs, not a facet assembly. ``previous``: the contact dofs' values at the last
    level's start (None: no prediction); :attr:`start` is this level's, after :meth:`run`."""

    def __init__(self, cond: Condensation, problem: DisplacementProblem, work: list[PETSc.Vec],
                 settings: NewtonSettings, scale: float, points: PointContact, previous: np.ndarray | None) -> None:
        super().__init__(cond, problem, work, settings, scale)
        self.points, self.previous = points, previous
        self.start: np.ndarray | None = None

    def run(self) -> tuple[list[float], np.ndarray, float]:
        cond, settings, pc = self.cond, self.settings, self.points
        cond.level()
        cond.u0.ghostUpdate(addv=PETSc.InsertMode.INSERT, mode=PETSc.ScatterMode.FORWARD)
        with cond.u0.localForm() as local:
            pc.level(local.array_r)
        v = self.dofs.gather(self.problem.u.vector.array_r[self.dofs.local])
        self.start = v
        history: list[float] = []
        r = pc.NB @ v + pc.c
        if not pc.state(r).any():  # a first contact (no point in contact at the start)
            scales = self._path_scales()
        else:
            scales = ()
        if scales:
            W = pc.W
            try:
                for s in scales:
                    pc.W = W * s
                    v, _ = self._iterate(v, history, STAGE_ITERATIONS, predict=False)
            finally:
                pc.W = W
            self.state = None
        v, snorm = self._iterate(v, history, settings.max_it * 8, predict=not scales)
        return history, v, snorm

    def _path_scales(self) -> tuple[float, ...]:
        """The compliance path's factors of the contact term (continuation.py's, on the reduced problem): the
        largest over the points of the contact's stiffness W p'(0+) times the point's compliance (N_B S N_B^T)_qq,
        R; the stages' s = ratio / R for ratio in RATIOS, where R > STIFF (else none)."""
        pc = self.points
        compliance = np.einsum("ij,ij->i", pc.NB @ self.cond.S, pc.NB.toarray())
        R = float(np.max(pc.W * np.nan_to_num(pc.inv_mu.astype(float)) * compliance, initial=0.0))
        return tuple(ratio / R for ratio in RATIOS) if R > STIFF else ()

    def _iterate(self, v: np.ndarray, history: list[float], limit: int, predict: bool) -> tuple[np.ndarray, float]:
        """The active-set iteration from v, at most ``limit`` steps (class docstring); appends ||F|| before each
        step taken to ``history``; returns the last v and the norm of the last step."""
        cond, settings, pc = self.cond, self.settings, self.points
        a, S = cond.u0_B, cond.S
        r = pc.NB @ v + pc.c
        state = pc.state(r)
        fnorm = self.fnorm(v - a + S @ pc.force(r))
        if predict and self.previous is not None and PREDICT > 0.0:  # the set the last two levels' motion leads to
            state = pc.state(pc.NB @ (v + PREDICT * (v - self.previous)) + pc.c)
        seen = [state.tobytes()]
        snorm = 0.0
        unorm = max(self.problem.u.vector.norm(), 1e-300)
        eye = np.eye(len(v))
        for _ in range(limit):
            self.state = state
            if fnorm <= settings.rtol * self.scale:
                self.state = None
                return v, snorm
            Hp = v - a + S @ pc.piece_force(r, state)  # H of the set's quadratic piece (H itself on v's set)
            d = -np.linalg.solve(eye + S @ pc.jacobian(state), Hp)
            s = pc.NB @ d
            ry = r + s
            statey = pc.state(ry)
            if np.array_equal(statey, state):  # the step solves its piece and stays in it: _polish takes it
                return v, snorm
            history.append(fnorm)
            y = v + d
            fy = self.fnorm(y - a + S @ pc.force(ry))
            if statey.tobytes() not in seen and (len(seen) <= FREE_STEPS or fy < fnorm):
                v, r, state, fnorm = y, ry, statey, fy
            else:
                w = sla.cho_solve(cond.chol, d)
                lam, state = pc.line_minimum(float((v - a) @ w), float(d @ w), r, s)
                v, r = v + lam * d, r + lam * s
                fnorm = self.fnorm(v - a + S @ pc.force(r))
            seen.append(state.tobytes())
            snorm = float(np.linalg.norm(d))
            if snorm <= settings.rtol * unorm and self.step_test(v, d):
                self.state = None
                return v, snorm
        self.state = None
        return v, snorm
