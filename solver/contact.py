"""Frictionless normal compliance on the contact parts: -sigma_nu = p(u_nu - g), p(r) = r_+ / mu.

UFL differentiates ``max_value`` to the Heaviside H(u_nu - g) / mu, which is the
semismooth Newton's generalized derivative.
"""

from __future__ import annotations

import ufl

from .config import BoundaryConfig
from .geometry import Geometry


def normal_compliance(r, mu: float):
    """p(r) = max(r, 0) / mu."""
    return ufl.max_value(r, 0.0) / mu


def penetration(u, n, gap: float):
    """u_nu - g (> 0 is interpenetration)."""
    return ufl.dot(u, n) - gap


def _ds(geo: Geometry, part: BoundaryConfig, degree: int):
    return geo.ds(geo.tags[part.name], metadata={"quadrature_degree": degree})


def residual(u, w, geo: Geometry, parts: tuple[BoundaryConfig, ...], degree: int):
    """j(u, w) = sum over contact parts of int p(u_nu - g) w_nu ds."""
    n = ufl.FacetNormal(geo.mesh)
    return sum(
        normal_compliance(penetration(u, n, p.gap), p.mu) * ufl.dot(w, n) * _ds(geo, p, degree) for p in parts
    )


def force(u, geo: Geometry, parts: tuple[BoundaryConfig, ...], degree: int):
    """Total normal contact force int p(u_nu - g) ds (a functional)."""
    n = ufl.FacetNormal(geo.mesh)
    return sum(normal_compliance(penetration(u, n, p.gap), p.mu) * _ds(geo, p, degree) for p in parts)


def active_length(u, geo: Geometry, parts: tuple[BoundaryConfig, ...], degree: int):
    """Length (area) of the contact zone where u_nu - g > 0, at the facet quadrature points."""
    n = ufl.FacetNormal(geo.mesh)
    return sum(
        ufl.conditional(ufl.gt(penetration(u, n, p.gap), 0.0), 1.0, 0.0) * _ds(geo, p, degree) for p in parts
    )

