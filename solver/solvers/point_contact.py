"""The contact term of newton_condensed on the contact dofs, at its quadrature points (2-D; docs/model.md §4).

u_nu - g = r(v) = N_B v + c on B's points, j_B(v) = N_B^T W p(r), C_BB = N_B^T W p'(r) N_B, with each point's law
from :mod:`solver.laws.contact`: the sparse products the reduced iteration (:mod:`reduced`) and its exact line
search work on, the same on every rank.
"""

from __future__ import annotations

import numpy as np
import scipy.sparse as sp
from dolfinx import fem

from solver.laws.contact import PointLaws
from solver.physics.contact_points import ContactPoints
from solver.solvers.contact_dofs import ContactDofs


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
