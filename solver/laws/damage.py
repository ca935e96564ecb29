"""Fremond's damage source phi(eps, zeta) (docs/model.md §2, (38)) and its slope in zeta, UFL and numpy side by side.

    phi(eps, zeta) = -lambda1 (1 - eta(zeta)) / eta(zeta) - (lambda2 Psi_q*(eps) / 2 - lambda3)_+
    Psi_q*(eps) = min(eps : eps, q*),    eta(zeta) = zeta if zeta > zeta* else zeta*

The UFL form is what the damage step assembles (:mod:`solver.solvers.damage_step`); the numpy form is its reference
and the semi-implicit step's stability bound reads the numpy slope. ``tests/laws/test_damage.py`` checks that the two
agree.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import ufl

from solver.errors import ConfigError

__all__ = ["FremondSource", "eta", "psi"]


def eta(zeta, zeta_star: float):
    """eta(zeta) = zeta if zeta > zeta*, zeta* otherwise (UFL)."""
    return ufl.conditional(ufl.gt(zeta, zeta_star), zeta, zeta_star)


def psi(eps, q_star: float):
    """Psi_q*(eps) = min(eps : eps, q*) (UFL)."""
    return ufl.min_value(ufl.inner(eps, eps), q_star)


@dataclass(frozen=True)
class FremondSource:
    """phi(eps, zeta) with the scene's ``damage.lambda1..3``, ``zeta_star``, ``q_star`` (checked at construction:
    a ConfigError whose key is the parameter's name)."""

    lambda1: float = 1e-2
    lambda2: float = 10.0
    lambda3: float = 0.0
    zeta_star: float = 0.01
    q_star: float = 1.0

    def __post_init__(self) -> None:
        if not 0 < self.zeta_star < 1:
            raise ConfigError(key="zeta_star", value=self.zeta_star, allowed="must be in (0, 1)")
        if not self.q_star > 0:
            raise ConfigError(key="q_star", value=self.q_star, allowed="must be > 0")
        for key, value in (("lambda1", self.lambda1), ("lambda2", self.lambda2), ("lambda3", self.lambda3)):
            if not value >= 0:
                raise ConfigError(key=key, value=value, allowed="must be >= 0")

    # --- UFL: the definition

    def ufl(self, eps, zeta) -> ufl.core.expr.Expr:
        """phi(eps, zeta) (UFL)."""
        e = eta(zeta, self.zeta_star)
        return -self.lambda1 * (1.0 - e) / e - ufl.max_value(0.5 * self.lambda2 * psi(eps, self.q_star) - self.lambda3,
                                                             0.0)

    def ufl_slope(self, zeta) -> ufl.core.expr.Expr:
        """d phi / d zeta = lambda1 / zeta^2 above zeta*, 0 below (UFL; docs/model.md §2)."""
        return ufl.conditional(ufl.gt(zeta, self.zeta_star), self.lambda1 / zeta**2, 0.0)

    # --- numpy: the same on arrays

    def numpy(self, eps: np.ndarray, zeta: np.ndarray) -> np.ndarray:
        """phi at strains eps (n, d, d) and damage values zeta (n,)."""
        e = np.where(zeta > self.zeta_star, zeta, self.zeta_star)
        q = np.minimum(np.einsum("nij,nij->n", eps, eps), self.q_star)
        return -self.lambda1 * (1.0 - e) / e - np.maximum(0.5 * self.lambda2 * q - self.lambda3, 0.0)

    def slope(self, zeta: np.ndarray) -> np.ndarray:
        """d phi / d zeta at damage values zeta (0 at and below zeta*)."""
        above = zeta > self.zeta_star
        out = np.zeros_like(zeta, dtype=float)
        out[above] = self.lambda1 / zeta[above] ** 2
        return out
