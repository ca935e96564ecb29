"""Frictionless normal compliance on the contact parts (docs/model.md §1, §3.3): -sigma_nu = p(u_nu - g).

The law p of each part is its :attr:`BoundaryConfig.contact_law` (solver/laws/contact.py: linear, power, limited
penetration, ...), whose UFL form is integrated here. UFL differentiates ``max_value`` to the Heaviside, which is
the semismooth Newton's generalized derivative (H(u_nu - g) / mu for the linear law). The gap is a number, a table
or an obstacle, the same values here (a field exact at the contact quadrature points) and at the points
(:mod:`solver.physics.gap`).
"""

from __future__ import annotations

import numpy as np
import ufl
from dolfinx import fem
from dolfinx.fem import petsc as fpetsc
from mpi4py import MPI
from petsc4py import PETSc

from solver.config import BoundaryConfig
from solver.laws.constants import constant
from solver.laws.contact import LinearLaw
from solver.mesh.geometry import Geometry
from solver.physics.gap import gap_function, gap_values  # noqa: F401  (gap_values: re-exported)
from solver.physics.operators import assemble_without_diagonal
from solver.physics.quadrature import ContactRule, contact_rule, facet_type


def normal_compliance(r: ufl.core.expr.Expr, mu: float) -> ufl.core.expr.Expr:
    """p(r) = max(r, 0) / mu (the linear law)."""
    return LinearLaw(mu).ufl(r)


def compliance(r: ufl.core.expr.Expr, part: BoundaryConfig) -> ufl.core.expr.Expr:
    """p(r) of the part's law, its UFL form."""
    return part.contact_law.ufl(r)


def penetration(u, n, gap):
    """u_nu - g (> 0 is interpenetration)."""
    return ufl.dot(u, n) - gap


def contact_ds(geo: Geometry, part: BoundaryConfig, degree: int | ContactRule):
    """The part's ``ds`` with the contact rule (a Gauss degree or a :class:`ContactRule`): every integral of the
    contact term and of what shares its points."""
    return geo.ds(geo.tags[part.name], metadata=contact_rule(degree).metadata(facet_type(geo.mesh)))


def residual(u, w, geo: Geometry, parts: tuple[BoundaryConfig, ...], degree: int | ContactRule):
    """j(u, w) = sum over contact parts of int p(u_nu - g) w_nu ds."""
    n = ufl.FacetNormal(geo.mesh)
    return sum(
        compliance(penetration(u, n, gap_function(p, geo, degree)), p) * ufl.dot(w, n) * contact_ds(geo, p, degree) for p in parts
    )


def force(u, geo: Geometry, parts: tuple[BoundaryConfig, ...], degree: int | ContactRule):
    """Total normal contact force int p(u_nu - g) ds (a functional)."""
    n = ufl.FacetNormal(geo.mesh)
    return sum(compliance(penetration(u, n, gap_function(p, geo, degree)), p) * contact_ds(geo, p, degree) for p in parts)


def active_length(u, geo: Geometry, parts: tuple[BoundaryConfig, ...], degree: int | ContactRule):
    """Length (area) of the contact zone where u_nu - g > 0, at the facet quadrature points."""
    n = ufl.FacetNormal(geo.mesh)
    return sum(
        ufl.conditional(ufl.gt(penetration(u, n, gap_function(p, geo, degree)), 0.0), 1.0, 0.0) * contact_ds(geo, p, degree)
        for p in parts
    )


class ContactTerm:
    """j(u, w) as a residual term and its Jacobian C, with C's active set tracked between calls.

    With the linear and limited-penetration laws the problem is piecewise linear, so C changes
    only when the active set does; with the power law it changes with u. A fingerprint C r
    (r a fixed random vector) tells whether C changed: a missed change could cost Newton
    iterations, never accuracy (the residual decides convergence). ``piecewise_linear``: every part's law is
    piecewise linear, so a Newton iterate depends only on the active set it was computed from.
    """

    def __init__(self, geo: Geometry, u: fem.Function, arguments: tuple, parts: tuple[BoundaryConfig, ...],
                 degree: int | ContactRule, bcs) -> None:
        du, w = arguments
        # the contact term's factor: 1 but while a first contact is solved by a continuation in the compliance
        # (solvers/continuation.py: s j(u) is the term of the laws s p, softer for s < 1)
        self.scale = fem.Constant(geo.mesh, PETSc.ScalarType(1.0))
        Fc = self.scale * residual(u, w, geo, parts, degree)
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
        self.piecewise_linear = all(p.contact_law.piecewise_linear for p in parts)
        self.linear = all(isinstance(p.contact_law, LinearLaw) for p in parts)  # every part's law p = r_+ / mu
        # int_Gamma_C (1/mu) n . w ds: the contact's normal at Gamma_C's nodes, scaled by its stiffness (normal_stiffness);
        # a law without a fixed stiffness (power: p'(r) = c m r^(m-1)) is left out
        stiff = [(p, p.contact_law.stiffness) for p in parts if p.contact_law.stiffness is not None]
        # the size of the contact term's summands where a point penetrates: (1/mu) (|u_nu| + |g|) n . w, whose
        # round-off (eps times it) is the residual's floor there, u_nu - g cancelling (roundoff)
        nrm = ufl.FacetNormal(geo.mesh)
        self._size_form = fem.form(sum(
            constant(w, k) * ufl.conditional(ufl.gt(penetration(u, nrm, gap_function(p, geo, degree)), 0.0),
                                             abs(ufl.dot(u, nrm)) + abs(gap_function(p, geo, degree)), 0.0)
            * ufl.dot(w, nrm) * contact_ds(geo, p, degree) for p, k in stiff)) if stiff else None
        self._size: PETSc.Vec | None = None  # made at the first roundoff (a direct solver's exact steps only)
        self._normal_form = fem.form(sum(constant(w, k) * ufl.dot(w, ufl.FacetNormal(geo.mesh)) * contact_ds(geo, p, degree)
                                         for p, k in stiff)) if stiff else None

    def normal_stiffness(self, out: PETSc.Vec) -> None:
        """out = int_Gamma_C (1/mu) n . w ds, ghosts included: at each node of Gamma_C a vector along the normal (the
        facet normals averaged with the weights int phi_i ds) whose length is the scale (1/mu) int phi_i ds of the
        contact's stiffness there (the law's :attr:`~solver.laws.contact.ContactLaw.stiffness`, 1/mu); zero elsewhere
        and on parts whose law has none (power). The iterative solver's near-nullspace reads it (newton.contact_normals)."""
        with out.localForm() as local:
            local.set(0.0)
        if self._normal_form is not None:
            fpetsc.assemble_vector(out, self._normal_form)
        out.ghostUpdate(addv=PETSc.InsertMode.ADD, mode=PETSc.ScatterMode.REVERSE)
        out.ghostUpdate(addv=PETSc.InsertMode.INSERT, mode=PETSc.ScatterMode.FORWARD)

    def roundoff(self) -> float:
        """eps times the norm of the contact term's summands at the current u ((1/mu)(|u_nu| + |g|) int phi n ds at
        the penetrating points): the residual's round-off floor from the contact term, where u_nu - g cancels and
        1/mu amplifies what is left (0 without a law of fixed stiffness). Collective."""
        if self._size_form is None:
            return 0.0
        if self._size is None:
            self._size = fpetsc.create_vector(self._size_form)
        with self._size.localForm() as local:
            local.set(0.0)
        fpetsc.assemble_vector(self._size, self._size_form)
        self._size.ghostUpdate(addv=PETSc.InsertMode.ADD, mode=PETSc.ScatterMode.REVERSE)
        fpetsc.set_bc(self._size, self.bcs, scale=0.0)
        return float(np.finfo(float).eps * self._size.norm())

    def add_residual(self, F: PETSc.Vec) -> float:
        """F += j(u, .) with the clamped rows zero; returns ||j(u, .)|| (F must be zero on entry)."""
        fpetsc.assemble_vector(F, self.residual_form)
        F.ghostUpdate(addv=PETSc.InsertMode.ADD, mode=PETSc.ScatterMode.REVERSE)
        fpetsc.set_bc(F, self.bcs, scale=0.0)
        return F.norm()

    def _fingerprint_at(self) -> np.ndarray:
        """C assembled at the current u, and this rank's part of its fingerprint C r (a view: copy to keep it)."""
        assemble_without_diagonal(self.C, self.jacobian_form, self.bcs)
        self.C.mult(self._probe, self._print)
        return self._print.array_r

    def assemble_jacobian(self) -> bool:
        """Assemble C at the current u; True if the active set (C) changed since the last call."""
        values = self._fingerprint_at()
        changed = self._last is None or not np.array_equal(values, self._last)
        changed = self.comm.allreduce(changed, op=MPI.LOR)
        if changed:
            self._last = values.copy()
        return changed

    def fingerprint(self) -> bytes:
        """This rank's part of the last assembled C's fingerprint (it identifies the active set)."""
        return b"" if self._last is None else self._last.tobytes()

    def active_set_at(self) -> bytes:
        """This rank's fingerprint of the active set at the current u, C assembled there (the last one recorded
        is left as it is: the next :meth:`assemble_jacobian` compares with it)."""
        return self._fingerprint_at().tobytes()

    def forget(self) -> None:
        """Treat the next Jacobian as new (after a restart: the matrix must be rebuilt)."""
        self._last = None
