"""Newton on the contact dofs alone (``solver.method = "newton_condensed"``; docs/model.md §4).

K is assembled once per run, and the contact term j(u) of a level acts only on the dofs of the contact facets
(B, the Dirichlet ones left out: a Lagrange trace on a facet depends on the facet's dofs only). Writing c = j_B(u)
for the contact force on them, the level's F(u) = K u + j(u) - b = 0 is

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
(:class:`PointContact`, :class:`PointReduced`): sparse products instead of facet assemblies, an exact line search
from the kinks of the piecewise-quadratic E, the active set looking ahead along the step after a damped one, and a
first set predicted from the last two levels (docs/model.md §4).

Only where it applies (:func:`applies`): a contact energy (no implicit memory term), a piecewise linear law, a
direct linear solver and at most MAX_CONTACT_DOFS contact dofs; elsewhere the method is newton_energy.
"""

from __future__ import annotations

import numpy as np
import scipy.linalg as sla
import scipy.sparse as sp
from dolfinx import fem
from dolfinx.fem import petsc as fpetsc
from mpi4py import MPI
from petsc4py import PETSc

from solver.config import SolverConfig
from solver.laws.contact import PointLaws
from solver.physics.contact_points import ContactPoints
from solver.physics.displacement import DisplacementProblem, SolveInfo
from solver.physics.operators import assemble_without_diagonal
from solver.solvers.damped_newton import DampedResult, has_energy, illinois_root
from solver.solvers.energy_newton import FREE_STEPS, EnergyNewtonSolver
from solver.solvers.linear import REASONS_SNES, OwnOptions, direct_options

MAX_CONTACT_DOFS = 3000  # S is dense: m^2 doubles on every rank, m solves with K to build it
POLISH_STEPS = 3  # full Newton steps solved through K after the condensed iteration, before a factorization
# the first step's active set is the one at v + PREDICT (v - v_prev), v_prev the last level's start: half the last
# level's motion guessed best on hard.toml with P2 (n = 16 / 32 / 48: 160 / 193 / 197 iterations at 0.5, 165 / 214 /
# 220 at 1, 179 / 222 / 228 without a prediction; scripts/nonlinear_bench.py's cases)
PREDICT = 0.5


def applies(problem: DisplacementProblem, settings: SolverConfig, m: int) -> bool:
    """Whether the condensation holds: an energy, a piecewise linear law, a direct solver, m small enough."""
    return (has_energy(problem) and problem.contact.piecewise_linear and settings.linear != "iterative"
            and 0 < m <= MAX_CONTACT_DOFS)


class ContactDofs:
    """The free dofs of the contact facets: this rank's owned ones (local indices) and the global order of all
    m of them (rank by rank), with the gathering of their values."""

    def __init__(self, u: fem.Function, facets: np.ndarray, fdim: int, bcs, comm: MPI.Comm) -> None:
        V = u.function_space
        bs = V.dofmap.index_map_bs
        owned = V.dofmap.index_map.size_local * bs
        blocks = fem.locate_dofs_topological(V, fdim, facets)
        local = np.unique((blocks[:, None] * bs + np.arange(bs)[None, :]).ravel())
        local = local[local < owned]
        probe = u.vector.duplicate()
        free = _free_mask(probe, bcs)
        probe.destroy()
        self.local = local[free[local]].astype(np.int32)
        self.comm = comm
        counts = comm.allgather(len(self.local))
        self.counts, self.m = counts, int(sum(counts))
        self.offset = int(sum(counts[:comm.rank]))
        self.global_index: np.ndarray | None = None  # their global indices (set at the first use)

    def gather(self, values: np.ndarray) -> np.ndarray:
        """All m values from each rank's owned ones (in the global order)."""
        if self.comm.size == 1:
            return np.array(values, dtype=float)
        out = np.empty(self.m)
        self.comm.Allgatherv(np.ascontiguousarray(values, dtype=float), [out, self.counts])
        return out

    def mine(self, values: np.ndarray) -> np.ndarray:
        """This rank's part of a global m-vector."""
        return values[self.offset:self.offset + len(self.local)]


def _free_mask(x: PETSc.Vec, bcs) -> np.ndarray:
    """True at the owned dofs no Dirichlet condition holds (set_bc with two x0 differ exactly there)."""
    one = x.duplicate()
    one.set(1.0)
    x.set(0.0)
    fpetsc.set_bc(x, bcs, one, 1.0)  # g - 1 on the prescribed dofs, 0 elsewhere
    a = x.array_r.copy()
    x.set(0.0)
    fpetsc.set_bc(x, bcs)  # g there
    one.destroy()
    return a == x.array_r


class PointContact:
    """The contact term on the contact dofs at its quadrature points (2-D; :class:`ContactPoints`), the same on every
    rank: u_nu - g = r(v) = N_B v + c (c: the level's other dofs and the gap), j_B(v) = N_B^T W p(r) and
    C_BB = N_B^T W p'(r) N_B. p is piecewise linear in each point's r, so along a line v + lam d every r_q is
    affine in lam and the level's energy is piecewise quadratic with its kinks where some r_q crosses 0 (or the
    limited-penetration depth): :meth:`line_minimum` finds its exact minimum from them."""

    def __init__(self, points: ContactPoints, dofs: ContactDofs, u: fem.Function) -> None:
        comm = dofs.comm
        index = fem.Function(u.function_space)  # each local dof's place among the m contact dofs (-1: none)
        index.x.array[:] = 0.0
        index.x.array[dofs.local] = dofs.offset + np.arange(len(dofs.local)) + 1.0
        index.x.scatter_forward()
        place = np.rint(index.x.array).astype(np.int64) - 1
        self.on_b = place >= 0  # the local dofs (ghosts too) on B
        N = points.N.tocoo()
        keep = self.on_b[N.col]
        counts = comm.allgather(points.N.shape[0])
        first = int(sum(counts[:comm.rank]))
        rows = comm.allgather(N.row[keep] + first)
        cols = comm.allgather(place[N.col[keep]])
        vals = comm.allgather(N.data[keep])
        self.q = int(sum(counts))
        self.NB = sp.csr_matrix((np.concatenate(vals), (np.concatenate(rows), np.concatenate(cols))),
                                shape=(self.q, dofs.m))
        self.NBT = self.NB.T.tocsr()
        self.N_rest = points.N  # this rank's points, all local dofs (B's are zeroed in the vector it is given)
        self.g = points.g
        self.comm = comm
        self.W = self._gathered(points.W)
        # every point's law, rank by rank (the points' order in N_B); all piecewise linear (applies)
        self.laws = PointLaws.join(comm.allgather(points.laws)) if comm.size > 1 else points.laws
        self.inv_mu = self.laws.column(lambda law: law.stiffness)
        self.c = np.zeros(self.q)

    def _gathered(self, a: np.ndarray) -> np.ndarray:
        """All ranks' point values, rank by rank (the points' order in N_B)."""
        a = np.asarray(a, dtype=float)
        return np.concatenate(self.comm.allgather(a)) if self.comm.size > 1 else a

    @staticmethod
    def applies(points: ContactPoints | None) -> bool:
        """Whether every point has a piecewise linear law."""
        return points is not None and points.laws.piecewise_linear

    def level(self, x: np.ndarray) -> None:
        """c for the level: x is u0's local array (ghosts included), whose values on B are left out."""
        self.c = self._gathered(self.N_rest @ np.where(self.on_b, 0.0, x) - self.g)

    def state(self, r: np.ndarray) -> np.ndarray:
        """Per point: the piece of its law r is on, 0 no contact (the active set)."""
        return self.laws.state(r)

    def slopes(self, state: np.ndarray) -> np.ndarray:
        """W p'(r) per point for an active set."""
        return self.W * self.laws.piece_slope(state)

    def pressure(self, r: np.ndarray) -> np.ndarray:
        """p(r) at the points (ContactPoints' law)."""
        return self.laws.pressure(r)

    def piece_force(self, r: np.ndarray, state: np.ndarray) -> np.ndarray:
        """j_B of an active set's quadratic piece at r: each point's law taken affine on its piece, zero off
        contact; j_B itself where the set is r's."""
        return self.NBT @ (self.W * self.laws.piece_pressure(r, state))

    def force(self, r: np.ndarray) -> np.ndarray:
        """j_B at the points' r."""
        return self.NBT @ (self.W * self.pressure(r))

    def jacobian(self, state: np.ndarray) -> np.ndarray:
        """C_BB (m x m, dense) for an active set."""
        return (self.NBT @ sp.diags(self.slopes(state)) @ self.NB).toarray()

    def kinks(self, r: np.ndarray, s: np.ndarray) -> np.ndarray:
        """The lam in (0, 1) where r + lam s crosses a kink of p, sorted."""
        lam = self.laws.crossings(r, s)
        return np.unique(lam[np.isfinite(lam) & (lam > 0.0) & (lam < 1.0)])

    def line_minimum(self, alpha: float, beta: float, r: np.ndarray, s: np.ndarray) -> tuple[float, np.ndarray]:
        """The exact minimum in (0, 1] of phi(lam) = E(v + lam d) and the active set just beyond it along d.

        phi'(lam) = alpha + lam beta + s.W p(r + lam s), with alpha = (v - P u0).S^{-1} d, beta = d.S^{-1} d and
        r, s the points' r at v and its change along d. phi' is continuous, piecewise linear and nondecreasing:
        its root is found by bisection over the kinks and one linear interpolation (1 where phi' < 0 up to the
        full step, or where d is no descent direction). The set returned is the one just past the minimum along
        d: a point the minimum stops at, on its kink, counts as entering contact where s > 0 (the directional
        derivative), so that Newton's next step sees the point that stopped this one."""
        def dphi(lam: float) -> float:
            return alpha + lam * beta + float(s @ (self.W * self.pressure(r + lam * s)))

        knots = np.concatenate([[0.0], self.kinks(r, s), [1.0]])
        values = {0: dphi(0.0)}
        lo, hi = 0, len(knots) - 1
        values[hi] = dphi(1.0)
        if values[hi] <= 0.0 or values[0] >= 0.0:  # E decreases up to the full step (or d is no descent)
            lam, after = 1.0, 1.0
        else:
            while hi - lo > 1:  # phi'(knots[lo]) < 0 <= phi'(knots[hi])
                mid = (lo + hi) // 2
                values[mid] = dphi(knots[mid])
                if values[mid] < 0.0:
                    lo = mid
                else:
                    hi = mid
            a, b = values[lo], values[hi]
            lam = knots[lo] + (knots[hi] - knots[lo]) * (-a / (b - a))
            if b == 0.0 or lam >= knots[hi] * (1.0 - 1e-12):  # the minimum is the kink itself
                lam = knots[hi]
                after = 0.5 * (knots[hi] + knots[hi + 1]) if hi + 1 < len(knots) else 1.0
            else:
                after = 0.5 * (lam + knots[hi])
        return float(lam), self.state(r + after * s)


class Condensation:
    """S = P K^{-1} P^T and its Cholesky factor, K's factorization, and the level's u0 = K^{-1} b."""

    def __init__(self, problem: DisplacementProblem, dofs: ContactDofs, comm: MPI.Comm, linear: str) -> None:
        self.problem, self.dofs = problem, dofs
        self.ksp = PETSc.KSP().create(comm)
        # options of its own, removed with it: a process that builds many models (a study, a sweep from
        # Python) would otherwise fill PETSc's options database (PETSc error 55 after some hundred)
        self.options = OwnOptions(self, "mech_condensed_", direct_options(comm, linear, True), ())
        self.ksp.setOptionsPrefix(self.options.prefix)
        self.ksp.setOperators(problem.stiffness())  # K, also after Newton steps wrote K + C into its storage (auto)
        self.ksp.setFromOptions()
        # K's factorization stays K's when a later full Newton iteration (newton_energy's, where the steps through
        # K do not settle a level) adds C into the same storage: PETSc would otherwise refactor it at the next solve
        self.ksp.getPC().setReusePreconditioner(True)
        self.u0 = problem.u.vector.duplicate()
        self._e = problem.u.vector.duplicate()
        self._z = problem.u.vector.duplicate()
        self.S = self._schur()
        self.chol = sla.cho_factor(self.S)

    def _schur(self) -> np.ndarray:
        """S, column by column: m solves with K (collective)."""
        dofs, e, z = self.dofs, self._e, self.u0
        rows = np.empty((len(dofs.local), dofs.m))
        for j in range(dofs.m):
            e.set(0.0)
            if dofs.offset <= j < dofs.offset + len(dofs.local):
                e.array[dofs.local[j - dofs.offset]] = 1.0
            self.ksp.solve(e, z)
            rows[:, j] = z.array_r[dofs.local]
        if dofs.comm.size == 1:
            S = rows
        else:
            S = np.vstack(dofs.comm.allgather(rows))
        return 0.5 * (S + S.T)  # symmetric up to round-off

    def level(self) -> np.ndarray:
        """u0 = K^{-1} b_n with the Dirichlet values of the level; returns P u0 (all m)."""
        self.ksp.solve(self.problem.ops.b, self.u0)
        fpetsc.set_bc(self.u0, self.problem.bcs)
        return self.dofs.gather(self.u0.array_r[self.dofs.local])

    def rebuild(self, c: np.ndarray, x: PETSc.Vec) -> None:
        """x = u0 - K^{-1} P^T c: the displacement in equilibrium inside for the contact forces c."""
        self.u0.copy(x)
        self.add_column_solve(-c, x)

    def add_column_solve(self, c: np.ndarray, x: PETSc.Vec) -> None:
        """x += K^{-1} P^T c (one solve with K)."""
        self._e.set(0.0)
        self._e.array[self.dofs.local] = self.dofs.mine(c)
        self.ksp.solve(self._e, self._z)
        x.axpy(1.0, self._z)


class CondensedNewtonSolver(EnergyNewtonSolver):
    """:class:`EnergyNewtonSolver` whose contact levels are solved on the contact dofs first (module docstring);
    where the condensation does not apply, energy_newton's method."""

    def __init__(self, problem: DisplacementProblem, settings: SolverConfig, comm: MPI.Comm, facets: np.ndarray,
                 fdim: int, points: ContactPoints | None = None) -> None:
        super().__init__(problem, settings, comm)
        self.dofs = ContactDofs(problem.u, facets, fdim, problem.bcs, comm) if self.energy else None
        self.on = self.energy and applies(problem, settings, self.dofs.m)
        # the contact term at its points on B (2-D): the reduced iteration of PointReduced; else Reduced's forms
        self.points = PointContact(points, self.dofs, problem.u) if self.on and PointContact.applies(points) \
            else None
        self.cond: Condensation | None = None  # built at the first level (its m solves count in the time loop)
        self.reduced_iterations = 0  # over the run
        self.previous: np.ndarray | None = None  # the contact dofs' values at the last level's start
        self.reduced_work = [problem.u.vector.duplicate() for _ in range(2)] if self.on else []

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
        if not self.on:
            return super().solve(scale)
        if self.cond is None:
            self.cond = Condensation(self.problem, self.dofs, self.problem.u.function_space.mesh.comm,
                                     self.settings.linear)
            self.factorizations += 1
            first = 1
        else:
            first = 0
        self.test.scale = scale
        reduced = (PointReduced if self.points is not None else Reduced)(self, scale)
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
                piece = (pc.jacobian(reduced.state), pc.piece_force(r, reduced.state) - pc.force(r))
            # (on v's own set Newton's step at u is that piece's solution, with C assembled as the residual is:
            # C from the points differs from it by round-off, which 1/mu = 1e12 makes worth a second step)
        out = self._polish(history, step, piece)
        if out.reason < 0:  # not settled by Newton steps solved through K: energy_newton's full iteration
            ksp = self.snes.getKSP()
            ksp.setOperators(self.problem.J, self.problem.J)
            full = self._iterate(ksp)
            self.problem.u.x.scatter_forward()
            self.factorizations += full.factorizations
            full.iterations += out.iterations
            full.history = [*out.history[:-1], *full.history]  # its first is out's last
            out = full
        out.factorizations += first  # K's, once per run
        name = REASONS_SNES.get(out.reason, str(out.reason))
        return self._finish(out, name, scale)

    def _step_through_k(self, u: PETSc.Vec, F: PETSc.Vec, d: PETSc.Vec, piece=None) -> float:
        """u += d, the full Newton step -J(u)^{-1} F(u) solved through K: d_B = -(I + S C)^{-1} P K^{-1} F on
        the contact dofs, d = -K^{-1} (F + P^T C d_B) elsewhere. Returns |d|. Two solves with K. ``piece``: (C_BB,
        dj_B) of the quadratic piece the reduced iteration ended on, the step then solving that piece (F + P^T dj_B
        is its residual); default: Newton's step, C assembled at u."""
        problem, dofs, cond = self.problem, self.dofs, self.cond
        if piece is not None:
            C, dj = piece
            F.array[dofs.local] += dofs.mine(dj)
        else:
            assemble_without_diagonal(problem.contact.C, problem.contact.jacobian_form, problem.contact.bcs)
            C = _block(problem.contact.C, dofs, u.getOwnershipRange()[0])
        cond.ksp.solve(F, d)  # K^{-1} F
        dB = -np.linalg.solve(np.eye(dofs.m) + cond.S @ C, dofs.gather(d.array_r[dofs.local]))
        d.scale(-1.0)
        cond.add_column_solve(-(C @ dB), d)
        d.array[dofs.local] = dofs.mine(dB)  # d_B itself (the contact term amplifies its error by 1/mu)
        fpetsc.set_bc(d, problem.bcs, scale=0.0)
        u.axpy(1.0, d)
        return d.norm()

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
            if out.reason != R.ITERATING:
                break
            if it == POLISH_STEPS:
                out.reason = R.DIVERGED_MAX_IT
                if keep is not None:
                    keep.copy(u)
                    out.history[-1], out.reason = keep_norm, R.CONVERGED_SNORM_RELATIVE
                break
            out.iterations += 1
            snorm = self._step_through_k(u, F, d, piece if it == 0 else None)
        if keep is not None:
            keep.destroy()
        u.ghostUpdate(addv=PETSc.InsertMode.INSERT, mode=PETSc.ScatterMode.FORWARD)
        problem.u.x.scatter_forward()
        return out


def _block(C: PETSc.Mat, dofs: ContactDofs, r0: int) -> np.ndarray:
    """C_BB (m x m, on every rank) from the assembled contact Jacobian. Collective."""
    rows = (dofs.local + r0).astype(np.int32)
    if dofs.global_index is None:
        dofs.global_index = np.concatenate(dofs.comm.allgather(rows)).astype(np.int32)
    block = C.getValues(rows, dofs.global_index).reshape(len(rows), dofs.m) if len(rows) else np.empty((0, dofs.m))
    return block if dofs.comm.size == 1 else np.vstack(dofs.comm.allgather(block))


class Reduced:
    """One level's iteration on v = P u (module docstring): Newton steps, full or with the exact line search."""

    def __init__(self, solver: CondensedNewtonSolver, scale: float) -> None:
        self.solver, self.cond, self.dofs = solver, solver.cond, solver.dofs
        self.problem = solver.problem
        self.x, self.F = solver.reduced_work  # the full vector the forms read (u0 with v on B), and j there
        self.scale = scale

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
        C = _block(contact.C, dofs, x.getOwnershipRange()[0])
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
        return step <= self.solver.settings.rtol * x.norm()

    def fnorm(self, H: np.ndarray) -> float:
        """||F(u(v))|| = ||S^{-1} H||."""
        return float(np.linalg.norm(sla.cho_solve(self.cond.chol, H)))

    def run(self) -> tuple[list[float], np.ndarray, float]:
        """Iterate from the current u's contact dofs; returns ||F|| before each step taken (one per iteration),
        v (converged or not: the full iteration that follows decides) and the norm of the last step (0 if none)."""
        cond, settings = self.cond, self.solver.settings
        cond.u0_B = cond.level()
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
    product on the m contact dofs, not a facet assembly."""

    def run(self) -> tuple[list[float], np.ndarray, float]:
        cond, settings, pc, solver = self.cond, self.solver.settings, self.solver.points, self.solver
        cond.u0_B = cond.level()
        cond.u0.ghostUpdate(addv=PETSc.InsertMode.INSERT, mode=PETSc.ScatterMode.FORWARD)
        with cond.u0.localForm() as local:
            pc.level(local.array_r)
        a, S = cond.u0_B, cond.S
        v = self.dofs.gather(self.problem.u.vector.array_r[self.dofs.local])
        r = pc.NB @ v + pc.c
        state = pc.state(r)
        fnorm = self.fnorm(v - a + S @ pc.force(r))
        if solver.previous is not None and PREDICT > 0.0:  # the set the last two levels' motion leads to
            state = pc.state(pc.NB @ (v + PREDICT * (v - solver.previous)) + pc.c)
        solver.previous = v
        seen, history = [state.tobytes()], []
        snorm = 0.0
        unorm = max(self.problem.u.vector.norm(), 1e-300)
        eye = np.eye(len(v))
        for _ in range(settings.max_it * 8):
            self.state = state
            if fnorm <= settings.rtol * self.scale:
                self.state = None
                return history, v, snorm
            Hp = v - a + S @ pc.piece_force(r, state)  # H of the set's quadratic piece (H itself on v's set)
            d = -np.linalg.solve(eye + S @ pc.jacobian(state), Hp)
            s = pc.NB @ d
            ry = r + s
            statey = pc.state(ry)
            if np.array_equal(statey, state):  # the step solves its piece and stays in it: _polish takes it
                return history, v, snorm
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
                return history, v, snorm
        self.state = None
        return history, v, snorm
