"""The physics of a scene's displacement problem, built once (docs/model.md §3.3):

    (A eps(u_n), eps(w)) + j(u_n, w) = (f_n, w)_V - (M_n, eps(w))    for all w

- :mod:`operators`: Dirichlet conditions (and the rigid-motion check), K, B and b_n, assembled once or once per
  level;
- :class:`contact.ContactTerm`: j(u, w), its Jacobian and the active set;
- :mod:`displacement`: F(u), J(u), and the residual carried from level to level;
- :class:`contact_points.ContactPoints` (2-D): the contact term at its quadrature points;
- :mod:`diagnostics`: what the time series reports about u, the reactions of the Dirichlet parts.

The method that solves it is built from these by methods.py.
"""

from __future__ import annotations

from dataclasses import dataclass

import ufl
from dolfinx import fem

from solver.config import BodyForceConfig, BoundaryConfig, MaterialConfig
from solver.mesh.geometry import Geometry
from solver.physics.contact import ContactTerm
from solver.physics.contact_points import ContactPoints
from solver.physics.diagnostics import DisplacementDiagnostics, Reactions
from solver.physics.displacement import DisplacementProblem
from solver.physics.memory import History
from solver.physics.memory_source import PointStrainNorm
from solver.physics.operators import Dirichlet, Operators, check_rigid_motions
from solver.physics.quadrature import ContactRule

PRESSURE_FLOOR = 1e-12  # a contact pressure below this times Young's modulus is round-off: no contact


@dataclass(frozen=True)
class DisplacementPhysics:
    """The parts of the displacement problem: the contact parts of the boundary, the contact term (None without
    contact), the operators, the level problem, the contact term at its points (2-D with contact, else None) and
    the diagnostics."""

    u: fem.Function
    parts: tuple[BoundaryConfig, ...]
    contact: ContactTerm | None
    ops: Operators
    problem: DisplacementProblem
    points: ContactPoints | None
    diagnostics: DisplacementDiagnostics


def build_physics(geo: Geometry, u: fem.Function, material: MaterialConfig, boundaries: tuple[BoundaryConfig, ...],
                  contact_degree: int | ContactRule, history: History | None = None, implicit_term=None,
                  body_force: BodyForceConfig | None = None) -> DisplacementPhysics:
    """The displacement problem's physics for the scene's boundaries (``contact_degree``: the contact term's
    rule, a :class:`~solver.physics.quadrature.ContactRule` or a Gauss degree)."""
    tractions = tuple(b for b in boundaries if b.role == "traction")
    parts = tuple(b for b in boundaries if b.role == "contact")
    deg = contact_degree
    dirichlet = Dirichlet(geo, u.function_space, boundaries)
    check_rigid_motions(geo, u.function_space, dirichlet)
    bcs = dirichlet.bcs
    arguments = (ufl.TrialFunction(u.function_space), ufl.TestFunction(u.function_space))
    contact = ContactTerm(geo, u, arguments, parts, deg, bcs) if parts else None
    # the contact Jacobian's stencil is part of K's sparsity, so K + C is formed in place
    pattern = contact.jacobian_ufl if contact is not None else None
    ops = Operators(geo, arguments, material, dirichlet, tractions, history, pattern_extra=pattern,
                    body_force=body_force)
    problem = DisplacementProblem(u, ops, contact, implicit_term)
    # the contact term at its points (2-D): the fixed-point methods and the penetration diagnostic
    points = ContactPoints(geo, u.function_space, parts, deg) if parts and geo.dim == 2 else None
    diagnostics = DisplacementDiagnostics(geo, u, parts, deg, points, Reactions(problem),
                                          point_strain_norm(ops, history, u),
                                          pressure_floor=PRESSURE_FLOOR * material.E)
    return DisplacementPhysics(u, parts, contact, ops, problem, points, diagnostics)


def point_strain_norm(ops: Operators, history: History | None, u: fem.Function) -> PointStrainNorm | None:
    """||eps(u)|| from the memory source's strain at its points, where its rule integrates eps : eps exactly
    (degree >= 2 (p - 1)); None (the Gram matrix) otherwise."""
    operator = ops.memory_operator
    if operator is None or history.rule.degree < 2 * (u.function_space.ufl_element().degree() - 1):
        return None
    return PointStrainNorm(history.H, operator.weights)
