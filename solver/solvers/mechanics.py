"""The displacement problem of one time level and the method that solves it (docs/model.md §3.3, §4).

    (A eps(u_n), eps(w)) + j(u_n, w) = (f_n, w)_V - (M_n, eps(w))    for all w

:class:`Mechanics` wires the parts together, each owning one idea:

- :mod:`operators`: Dirichlet conditions (and the rigid-motion check), K, B and b_n, assembled
  once or once per level;
- :class:`contact.ContactTerm`: j(u, w), its Jacobian and the active set;
- :mod:`displacement`: F(u), J(u), and the residual carried from level to level;
- :mod:`newton` / :mod:`fixed_point`: the methods (``solver.method``), one interface ``solve(scale)``;
- :mod:`diagnostics`: what the time series reports about u, the reactions of the Dirichlet parts.
"""

from __future__ import annotations

import numpy as np
import ufl
from dolfinx import fem

from solver.config import BodyForceConfig, BoundaryConfig, MaterialConfig, SolverConfig
from solver.errors import DisplacementSolveError
from solver.mesh.geometry import Geometry
from solver.physics.contact import ContactTerm
from solver.physics.contact_points import ContactPoints
from solver.physics.diagnostics import DisplacementDiagnostics, Reactions
from solver.physics.displacement import DisplacementProblem, SolveInfo
from solver.physics.memory import History
from solver.physics.memory_source import PointStrainNorm
from solver.physics.operators import Dirichlet, Operators, check_rigid_motions
from solver.solvers.auto import AutoSolver
from solver.solvers.condensed import CondensedNewtonSolver
from solver.solvers.energy_newton import EnergyNewtonSolver
from solver.solvers.fixed_point import FixedPointSolver, PenaltyDualitySolver
from solver.solvers.newton import NewtonSolver

__all__ = ["Mechanics", "SolveInfo", "DisplacementSolveError"]


PRESSURE_FLOOR = 1e-12  # a contact pressure below this times Young's modulus is round-off: no contact


class Mechanics:
    """u_n for each level: ``solve(t)``; plus the state a checkpoint carries and the diagnostics."""

    def __init__(self, geo: Geometry, u: fem.Function, material: MaterialConfig,
                 boundaries: tuple[BoundaryConfig, ...], settings: SolverConfig, history: History | None = None,
                 implicit_term=None, body_force: BodyForceConfig | None = None) -> None:
        self.u = u
        tractions = tuple(b for b in boundaries if b.role == "traction")
        parts = tuple(b for b in boundaries if b.role == "contact")
        deg = settings.contact_quadrature_degree
        dirichlet = Dirichlet(geo, u.function_space, boundaries)
        check_rigid_motions(geo, u.function_space, dirichlet)
        bcs = dirichlet.bcs
        arguments = (ufl.TrialFunction(u.function_space), ufl.TestFunction(u.function_space))
        self.contact = ContactTerm(geo, u, arguments, parts, deg, bcs) if parts else None
        # the contact Jacobian's stencil is part of K's sparsity, so K + C is formed in place
        pattern = self.contact.jacobian_ufl if self.contact is not None else None
        self.ops = Operators(geo, arguments, material, dirichlet, tractions, history, pattern_extra=pattern,
                             body_force=body_force)
        self.problem = DisplacementProblem(u, self.ops, self.contact, implicit_term)
        # the contact term at its points (2-D): the fixed-point methods and the penetration diagnostic
        points = ContactPoints(geo, u.function_space, parts, deg) if parts and geo.dim == 2 else None
        self.method = settings.method if parts else "newton"
        if self.method == "newton":
            self.solver = NewtonSolver(self.problem, settings, geo.comm)
        elif self.method == "newton_energy":
            self.solver = EnergyNewtonSolver(self.problem, settings, geo.comm)
        elif self.method in ("newton_condensed", "auto"):
            facets = np.concatenate([geo.facets(p.name) for p in parts])
            kind = CondensedNewtonSolver if self.method == "newton_condensed" else AutoSolver
            self.solver = kind(self.problem, settings, geo.comm, facets, geo.dim - 1, points)
        elif self.method == "fixed_point":
            self.solver = FixedPointSolver(self.problem, points, settings, geo.comm)
        else:
            self.solver = PenaltyDualitySolver(self.problem, points, settings, geo.comm, geo, parts)
        self.diagnostics = DisplacementDiagnostics(geo, u, parts, deg, points, Reactions(self.problem),
                                                   _point_strain_norm(self.ops, history, u),
                                                   pressure_floor=PRESSURE_FLOOR * material.E)

    def solve(self, t: float) -> SolveInfo:
        """Solve for u at time t (u holds the previous level as initial guess)."""
        return self.solver.solve(self.problem.begin_level(t))

    # ------------------------------------------------------------------ checkpoints
    def state(self) -> dict[str, np.ndarray]:
        """Vectors carried from one level to the next (the first residual of a level is derived from them)."""
        return {"F_last": self.problem.F_last.array, "b": self.ops.b.array, **self._solver_state()}

    def _solver_state(self) -> dict[str, np.ndarray]:
        """The displacement method's own carried arrays (newton_condensed's predictor; none for the others)."""
        state = getattr(self.solver, "state", None)
        return state() if state is not None else {}

    def scalars(self) -> dict[str, float]:
        own = getattr(self.solver, "scalars", None)  # the method's own (auto: the level it switched at)
        return {"c_norm": self.problem.contact_norm, "reuse": float(self.problem.carried),
                **(own() if own is not None else {})}

    def restore_vector(self, name: str, values: np.ndarray) -> None:
        """Set a carried vector (owned values) from a checkpoint."""
        own = {"F_last": self.problem.F_last, "b": self.ops.b}
        if name in own:
            own[name].array[:] = values.ravel()
        else:  # the method's own (state() named it)
            self.solver.restore(name, values)

    def restore_scalars(self, scalars: dict[str, float]) -> None:
        """Continue exactly where a checkpointed run was (the Jacobian is rebuilt at the first solve)."""
        self.problem.contact_norm = float(scalars["c_norm"])
        self.problem.carried = bool(scalars["reuse"])
        own = getattr(self.solver, "restore_scalars", None)
        if own is not None:
            own({k: v for k, v in scalars.items() if k not in ("c_norm", "reuse")})


def _point_strain_norm(ops: Operators, history: History | None, u: fem.Function) -> PointStrainNorm | None:
    """||eps(u)|| from the memory source's strain at its points, where its rule integrates eps : eps exactly
    (degree >= 2 (p - 1)); None (the Gram matrix) otherwise."""
    operator = ops.memory_operator
    if operator is None or history.rule.degree < 2 * (u.function_space.ufl_element().degree() - 1):
        return None
    return PointStrainNorm(history.H, operator.weights)
