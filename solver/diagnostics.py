"""Per-level diagnostics of the displacement: contact force and zone, penetration, ||eps(u)||.

Functionals of the contact term are integrated with the same facet rule as the term
itself; ||eps(u)||_L2 = sqrt(u . G u) with the strain Gram matrix G assembled once.
"""

from __future__ import annotations

import numpy as np
import ufl
from dolfinx import fem
from dolfinx.fem import petsc as fpetsc
from mpi4py import MPI

from . import contact
from .config import BoundaryConfig
from .contact_points import ContactPoints
from .geometry import Geometry
from .material import strain


class DisplacementDiagnostics:
    """What the time series reports about u at each level (all values the same on every rank)."""

    def __init__(self, geo: Geometry, u: fem.Function, parts: tuple[BoundaryConfig, ...], degree: int,
                 points: ContactPoints | None) -> None:
        self.geo, self.u, self.points = geo, u, points
        self.has_contact = bool(parts)
        self.force_form = fem.form(contact.force(u, geo, parts, degree)) if parts else None
        self.length_form = fem.form(contact.active_length(u, geo, parts, degree)) if parts else None
        V = u.function_space
        du, w = ufl.TrialFunction(V), ufl.TestFunction(V)
        self.gram = fpetsc.assemble_matrix(fem.form(ufl.inner(strain(du), strain(w)) * ufl.dx))
        self.gram.assemble()
        self._work = self.gram.createVecLeft()

    def _integral(self, form) -> float:
        return 0.0 if form is None else self.geo.comm.allreduce(fem.assemble_scalar(form), op=MPI.SUM)

    def contact_force(self) -> float:
        """Total normal contact force int p(u_nu - g) ds."""
        return self._integral(self.force_form)

    def contact_length(self) -> float:
        """Length (area) of the zone where u_nu > g, at the facet quadrature points."""
        return self._integral(self.length_form)

    def max_penetration(self) -> float:
        """Largest u_nu - g over the contact quadrature points (0 without contact, NaN in 3-D: not computed)."""
        if self.points is not None:
            return self.points.max_penetration(self.u.x.array)
        return float("nan") if self.has_contact else 0.0

    def strain_norm(self) -> float:
        """||eps(u)||_L2 = sqrt(u . G u)."""
        self.gram.mult(self.u.vector, self._work)
        return float(np.sqrt(max(self._work.dot(self.u.vector), 0.0)))

    def row(self) -> dict[str, float]:
        return {"contact_force": self.contact_force(), "contact_length": self.contact_length(),
                "max_penetration": self.max_penetration(), "strain_norm": self.strain_norm()}


class DamageDiagnostics:
    """Range and L2 norm of zeta at each level (a constant zeta0 when the scene has no damage)."""

    def __init__(self, mesh, damage, zeta0: float) -> None:
        self.comm = mesh.comm
        self.zeta = damage.zeta if damage is not None else None
        self.zeta0 = zeta0
        if self.zeta is not None:  # ||zeta||^2 = zeta . M zeta, with the mass matrix assembled once
            Z = self.zeta.function_space
            z, xi = ufl.TrialFunction(Z), ufl.TestFunction(Z)
            self.mass = fpetsc.assemble_matrix(fem.form(z * xi * ufl.dx))
            self.mass.assemble()
            self._work = self.mass.createVecLeft()
        else:
            area = self.comm.allreduce(fem.assemble_scalar(fem.form(1.0 * ufl.dx(domain=mesh))), op=MPI.SUM)
            self._constant_norm = zeta0 * float(np.sqrt(area))

    def zeta_range(self) -> tuple[float, float]:
        if self.zeta is None:
            return self.zeta0, self.zeta0
        n = self.zeta.function_space.dofmap.index_map.size_local
        a = self.zeta.x.array[:n]
        return (self.comm.allreduce(float(a.min()) if n else np.inf, op=MPI.MIN),
                self.comm.allreduce(float(a.max()) if n else -np.inf, op=MPI.MAX))

    def zeta_norm(self) -> float:
        if self.zeta is None:
            return self._constant_norm
        self.mass.mult(self.zeta.vector, self._work)
        return float(np.sqrt(max(self._work.dot(self.zeta.vector), 0.0)))
