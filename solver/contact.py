"""Frictionless normal compliance on the contact parts (docs/model.md §1, §3.3): -sigma_nu = p(u_nu - g), p(r) = r_+ / mu.

UFL differentiates ``max_value`` to the Heaviside H(u_nu - g) / mu, which is the
semismooth Newton's generalized derivative.
"""

from __future__ import annotations

import numpy as np
import ufl
from dolfinx import fem
from dolfinx.fem import petsc as fpetsc
from mpi4py import MPI
from petsc4py import PETSc

from .config import BoundaryConfig
from .geometry import Geometry
from .operators import assemble_without_diagonal


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


class ContactTerm:
    """j(u, w) as a residual term and its Jacobian C, with C's active set tracked between calls.

    The problem is piecewise linear, so C changes only when the active set does. A fingerprint
    C r (r a fixed random vector) tells whether it did: a missed change could cost Newton
    iterations, never accuracy (the residual decides convergence).
    """

    def __init__(self, geo: Geometry, u: fem.Function, arguments: tuple, parts: tuple[BoundaryConfig, ...],
                 degree: int, bcs) -> None:
        du, w = arguments
        Fc = residual(u, w, geo, parts, degree)
        self.residual_form = fem.form(Fc)
        self.jacobian_ufl = ufl.derivative(Fc, u, du)
        self.jacobian_form = fem.form(self.jacobian_ufl)
        self.C = fpetsc.create_matrix(self.jacobian_form)
        self.bcs = bcs
        self.comm = geo.comm
        self._probe = self.C.createVecRight()
        self._probe.setRandom(PETSc.Random().create(comm=geo.comm))
        self._print = self.C.createVecLeft()
        self._last: np.ndarray | None = None

    def add_residual(self, F: PETSc.Vec) -> float:
        """F += j(u, .) with the clamped rows zero; returns ||j(u, .)|| (F must be zero on entry)."""
        fpetsc.assemble_vector(F, self.residual_form)
        F.ghostUpdate(addv=PETSc.InsertMode.ADD, mode=PETSc.ScatterMode.REVERSE)
        fpetsc.set_bc(F, self.bcs, scale=0.0)
        return F.norm()

    def assemble_jacobian(self) -> bool:
        """Assemble C at the current u; True if the active set (C) changed since the last call."""
        assemble_without_diagonal(self.C, self.jacobian_form, self.bcs)
        self.C.mult(self._probe, self._print)
        values = self._print.array_r
        changed = self._last is None or not np.array_equal(values, self._last)
        changed = self.comm.allreduce(changed, op=MPI.LOR)
        if changed:
            self._last = values.copy()
        return changed

    def forget(self) -> None:
        """Treat the next Jacobian as new (after a restart: the matrix must be rebuilt)."""
        self._last = None
