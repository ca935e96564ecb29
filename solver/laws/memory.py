"""The memory integrand H = zeta Phi_L(A eps) (docs/model.md §2, §3.1, §3.4): what the memory kernel integrates.

One law for 2-D (plane stress or plane strain, in-plane part), plane strain's out-of-plane part H_33 and 3-D: A eps =
lambda tr(eps) I + 2 mu eps with the model's Lame constants, Phi_L the componentwise truncation at L. The UFL form
is the definition; the numpy form evaluates it on the compact strain components (xx, yy[, zz], then xy[, yz, xz],
one row per component, as :data:`pairs` orders them), the fast path of :mod:`solver.physics.memory_source`.
``tests/laws/test_memory.py`` checks that the two agree.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import ufl

from solver.errors import ConfigError
from solver.laws.constants import constant

__all__ = ["MemoryIntegrand", "pairs", "truncate"]


def pairs(d: int) -> list[tuple[int, int]]:
    """The independent components (i, j) of a symmetric d x d tensor: the diagonal first, then i < j."""
    return [(i, i) for i in range(d)] + [(i, j) for i in range(d) for j in range(i + 1, d)]


def truncate(tau, L: float) -> ufl.core.expr.Expr:
    """Componentwise truncation Phi_L(tau)_ij = max(-L, min(L, tau_ij)) (UFL)."""
    n, m = tau.ufl_shape
    return ufl.as_matrix([[ufl.max_value(-L, ufl.min_value(L, tau[i, j])) for j in range(m)] for i in range(n)])


@dataclass(frozen=True)
class MemoryIntegrand:
    """H(eps, zeta) = zeta Phi_L(A eps), A eps = lambda tr(eps) I + 2 mu eps (docs/model.md §2).

    ``L``: the truncation (``memory.L``, > 0); ``lame_lambda``, ``lame_mu``: A's Lame constants for the
    material model (plane stress's lambda* in plane stress). In plane strain eps_33 = 0, so (A eps)_33 =
    lambda tr(eps) and, Phi_L acting componentwise, H_33 = zeta Phi_L(lambda tr(eps)) (:meth:`ufl_out_of_plane`).
    """

    L: float
    lame_lambda: float
    lame_mu: float

    def __post_init__(self) -> None:
        self.check_truncation(self.L)

    @staticmethod
    def check_truncation(L: float) -> None:
        """Raise a ConfigError (key ``L``) unless L > 0: the scene's ``memory.L`` is checked here."""
        if not L > 0:
            raise ConfigError(key="L", value=L, allowed="must be > 0")

    # --- UFL: the definition

    def stress(self, eps) -> ufl.core.expr.Expr:
        """A eps (UFL)."""
        d = eps.ufl_shape[0]
        return constant(eps, self.lame_lambda) * ufl.tr(eps) * ufl.Identity(d) + 2.0 * constant(eps, self.lame_mu) * eps

    def ufl(self, eps, zeta) -> ufl.core.expr.Expr:
        """zeta Phi_L(A eps) (UFL), the d x d integrand."""
        return zeta * truncate(self.stress(eps), constant(eps, self.L))

    def ufl_out_of_plane(self, eps, zeta) -> ufl.core.expr.Expr:
        """H_33 = zeta Phi_L(lambda tr(eps)) of plane strain (UFL), eps the in-plane strain."""
        L = constant(eps, self.L)
        return zeta * ufl.max_value(-L, ufl.min_value(L, constant(eps, self.lame_lambda) * ufl.tr(eps)))

    # --- numpy: the same on compact components, into caller-owned buffers

    def compact(self, eps: np.ndarray, zeta: np.ndarray | float, out: np.ndarray, trace: np.ndarray,
                scale: float = 1.0) -> np.ndarray:
        """scale zeta Phi_L(A eps) on the compact components (component, point) of d x d tensors, into ``out``
        (eps's shape; ``trace`` one row of work). The truncation is skipped where no value reaches L: it is then
        the identity (a NaN skips it and stays, as np.clip would keep it)."""
        d = {3: 2, 6: 3}[len(eps)]
        a = np.multiply(eps, 2.0 * self.lame_mu, out=out)
        tr = np.add(eps[0], eps[1], out=trace)
        for i in range(2, d):
            tr += eps[i]
        tr *= self.lame_lambda
        a[:d] += tr
        if a.max() > self.L or a.min() < -self.L:
            np.clip(a, -self.L, self.L, out=a)
        a *= zeta * scale if scale != 1.0 else zeta
        return a

    def out_of_plane(self, eps: np.ndarray, zeta: np.ndarray | float, scale: float = 1.0) -> np.ndarray:
        """scale H_33 from the in-plane compact components (xx, yy first), a new array."""
        h = eps[0] + eps[1]
        h *= self.lame_lambda
        np.clip(h, -self.L, self.L, out=h)
        h *= zeta * scale if scale != 1.0 else zeta
        return h

    def full(self, eps: np.ndarray, zeta: np.ndarray | float) -> np.ndarray:
        """H of full tensors eps (n, d, d) (symmetric) and zeta (n,): (n, d, d). A reference form, not a fast one."""
        d = eps.shape[-1]
        comps = np.array([eps[:, i, j] for i, j in pairs(d)])
        h = self.compact(comps, zeta, np.empty_like(comps), np.empty(comps.shape[1]))
        out = np.empty_like(eps)
        for c, (i, j) in enumerate(pairs(d)):
            out[:, i, j] = out[:, j, i] = h[c]
        return out
