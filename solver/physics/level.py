"""The displacement problem of one time level, declared once in UFL (docs/model.md §3.3, §3.4).

Find u_n in V^h, u_n = g_n on Gamma_D, such that for every w in V^h (w = 0 on Gamma_D):

    F(u_n; w) =   (A eps(u_n), eps(w))                            a(u_n, w)    elasticity, §2, §3.3
                + j(u_n, w)                                       normal compliance on Gamma_C, §3.3
                + (k/2) g(0) (zeta_n Phi_L(A eps(u_n)), eps(w))   F_m(u_n; w)  implicit trapezoid only, §3.4
                - (f0_n, w) - (f2_n, w)_{Gamma_N}                 l_n(w)       loads, §1
                + (M_n, eps(w))                                   memory sum M_n of the past, §3.4
              = 0,

    J(u_n; du, w) = dF/du [du] = a(du, w) + C(u_n)[du, w] (+ dF_m/du[du, w])   (UFL's generalized derivative)

Each term is built by the module that owns it (:class:`operators.Operators`: a, l_n and (M_n, eps(w));
:func:`contact.residual`: j; :func:`memory.trapezoid_term`: F_m); here they are only put together.
:class:`displacement.DisplacementProblem` evaluates the same F and J faster, through the split
F(u) = K u + j(u) - b_n (:class:`displacement.FixedSplit`); tests/physics/test_level.py checks that the two agree.
"""

from __future__ import annotations

from dataclasses import dataclass

import ufl
from dolfinx import fem

from solver.config import BoundaryConfig
from solver.mesh.geometry import Geometry
from solver.physics import contact
from solver.physics.operators import Operators
from solver.physics.quadrature import ContactRule


@dataclass(frozen=True)
class LevelForms:
    """The terms of F(u; w) above as UFL forms, u the level's unknown, (du, w) the trial and test functions.

    ``stiffness`` is bilinear in (du, w), ``loads`` and ``memory`` are linear in w, ``contact`` and
    ``implicit_memory`` are nonlinear in u; an absent term is None.
    """

    u: fem.Function
    du: ufl.Argument
    w: ufl.Argument
    stiffness: ufl.Form  # a(du, w) = (A eps(du), eps(w))
    loads: ufl.Form  # l_n(w) = (f0_n, w) + (f2_n, w)_{Gamma_N}
    contact: ufl.Form | None = None  # j(u, w)
    memory: ufl.Form | None = None  # (M_n, eps(w))
    implicit_memory: ufl.Form | None = None  # F_m(u; w)

    @property
    def residual(self) -> ufl.Form:
        """F(u; w) = a(u, w) + j(u, w) + F_m(u; w) - l_n(w) + (M_n, eps(w))."""
        F = ufl.action(self.stiffness, self.u) - self.loads
        for term in (self.contact, self.implicit_memory, self.memory):
            if term is not None:
                F = F + term
        return F

    @property
    def jacobian(self) -> ufl.Form:
        """J(u; du, w) = dF/du [du]."""
        return ufl.derivative(self.residual, self.u, self.du)

    @property
    def fixed_stiffness(self) -> bool:
        """Whether F = K u + j(u) - b_n with K the matrix of ``stiffness``: true unless F_m is present."""
        return self.implicit_memory is None


def declare_level(geo: Geometry, u: fem.Function, ops: Operators, contact_parts: tuple[BoundaryConfig, ...],
                  contact_degree: int | ContactRule, implicit_memory: ufl.Form | None = None) -> LevelForms:
    """The level's forms from the builders of each term: ``ops`` (a, l_n, (M_n, eps(w))), the contact parts
    and their rule (j: a Gauss degree or a ContactRule), and F_m as the problem holds it (``DisplacementProblem.implicit_memory``)."""
    j = contact.residual(u, ops.w, geo, contact_parts, contact_degree) if contact_parts else None
    return LevelForms(u, ops.du, ops.w, stiffness=ops.bulk, loads=ops.load_ufl, contact=j, memory=ops.memory_ufl,
                      implicit_memory=implicit_memory)
