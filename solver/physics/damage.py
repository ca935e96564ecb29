"""The damage law (docs/model.md §1, §2): Fremond's source phi and its truncations, as pure UFL.

The damage equation's discrete steps, which solve with it, are :mod:`solver.solvers.damage`.
"""

from __future__ import annotations

import ufl

from solver.config import DamageConfig

__all__ = ["eta", "psi", "source"]


def eta(zeta, zeta_star: float):
    """eta(zeta) = zeta if zeta > zeta*, zeta* otherwise."""
    return ufl.conditional(ufl.gt(zeta, zeta_star), zeta, zeta_star)


def psi(eps, q_star: float):
    """Psi_q*(u) = min(eps(u) . eps(u), q*)."""
    return ufl.min_value(ufl.inner(eps, eps), q_star)


def source(eps, zeta, cfg: DamageConfig):
    """phi(eps, zeta) = -lambda1 (1 - eta) / eta - (lambda2 Psi / 2 - lambda3)_+."""
    e = eta(zeta, cfg.zeta_star)
    return -cfg.lambda1 * (1.0 - e) / e - ufl.max_value(0.5 * cfg.lambda2 * psi(eps, cfg.q_star) - cfg.lambda3, 0.0)
