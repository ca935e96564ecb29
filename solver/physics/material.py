"""Constitutive functions as pure UFL (docs/model.md §2): elasticity A, its out-of-plane stress in plane strain,
von Mises; the truncation Phi_L is the memory law's (:mod:`solver.laws.memory`, re-exported here)."""

from __future__ import annotations

import numpy as np
import ufl

from solver.laws.constants import constant
from solver.laws.memory import truncate

__all__ = ["elasticity", "lame", "out_of_plane_stress", "strain", "truncate", "von_mises", "von_mises_array"]


def lame(E: float, nu: float, model: str) -> tuple[float, float]:
    """(lambda, mu) of A for the model; plane stress uses lambda* = E nu / (1 - nu^2)."""
    mu = E / (2.0 * (1.0 + nu))
    if model == "plane_stress":
        return E * nu / (1.0 - nu**2), mu
    return E * nu / ((1.0 + nu) * (1.0 - 2.0 * nu)), mu


def strain(u) -> ufl.core.expr.Expr:
    """Linearized strain eps(u)."""
    return ufl.sym(ufl.grad(u))


def elasticity(eps, E: float, nu: float, model: str) -> ufl.core.expr.Expr:
    """A eps = lambda tr(eps) I + 2 mu eps."""
    lam, mu = (constant(eps, c) for c in lame(E, nu, model))  # a sweep of E or nu compiles nothing new
    d = eps.ufl_shape[0]
    return lam * ufl.tr(eps) * ufl.Identity(d) + 2.0 * mu * eps


def out_of_plane_stress(eps, E: float, nu: float) -> ufl.core.expr.Expr:
    """(A eps)_33 in plane strain (eps_33 = 0): lambda (eps_11 + eps_22)."""
    lam, _ = lame(E, nu, "plane_strain")
    return constant(eps, lam) * ufl.tr(eps)


def von_mises(tau, s33=None) -> ufl.core.expr.Expr:
    """The paper's von Mises norm of a plane stress field (2-D); with the out-of-plane stress
    ``s33`` (plane strain) the full formula; the usual one in 3-D."""
    if tau.ufl_shape[0] == 2 and s33 is not None:
        a, b, c = tau[0, 0], tau[1, 1], s33
        return ufl.sqrt(((a - b) ** 2 + (b - c) ** 2 + (c - a) ** 2) / 2 + 3 * tau[0, 1] ** 2)
    if tau.ufl_shape[0] == 2:
        return ufl.sqrt(tau[0, 0] ** 2 + tau[1, 1] ** 2 - tau[0, 0] * tau[1, 1] + 3 * tau[0, 1] ** 2)
    s = ufl.dev(tau)
    return ufl.sqrt(1.5 * ufl.inner(s, s))


def von_mises_array(s: np.ndarray, dim: int, s33: np.ndarray | None = None) -> np.ndarray:
    """von Mises of an array of tensors (n, dim*dim): the paper's plane formula in 2-D; with the
    out-of-plane stresses ``s33`` (plane strain) the full one, sqrt(((a-b)^2 + (b-c)^2 + (c-a)^2)/2 + 3 t^2)."""
    s = s.reshape(-1, dim, dim)
    if dim == 2 and s33 is not None:
        a, b, c, t = s[:, 0, 0], s[:, 1, 1], s33, s[:, 0, 1]
        return np.sqrt(((a - b) ** 2 + (b - c) ** 2 + (c - a) ** 2) / 2 + 3 * t * t)
    if dim == 2:
        a, b, c = s[:, 0, 0], s[:, 1, 1], s[:, 0, 1]
        return np.sqrt(a * a + b * b - a * b + 3 * c * c)
    dev = s - np.trace(s, axis1=1, axis2=2)[:, None, None] * np.eye(3) / 3
    return np.sqrt(1.5 * np.einsum("nij,nij->n", dev, dev))
