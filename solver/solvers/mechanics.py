"""The displacement of each level: the scene's physics (displacement_physics.py) solved by the scene's method
(methods.py), one level per :meth:`Mechanics.solve` (docs/model.md §3.3, §4).

:func:`build_mechanics` builds both once; :class:`Mechanics` solves the levels and says what a checkpoint carries:
the problem's carried residual and load, and the method's own state (:class:`~method.DisplacementMethod`).
"""

from __future__ import annotations

import numpy as np
from dolfinx import fem

from solver.config import BodyForceConfig, BoundaryConfig, MaterialConfig
from solver.errors import DisplacementSolveError
from solver.mesh.geometry import Geometry
from solver.physics.displacement import SolveInfo
from solver.physics.memory import History
from solver.solvers.displacement_physics import PRESSURE_FLOOR, DisplacementPhysics, build_physics
from solver.solvers.method import DisplacementMethod
from solver.solvers.methods import MethodContext, build_method
from solver.solvers.settings import MethodSettings

__all__ = ["Mechanics", "build_mechanics", "SolveInfo", "DisplacementSolveError", "PRESSURE_FLOOR"]


class Mechanics:
    """u_n for each level: ``solve(t)`` by ``solver`` on ``physics``; plus the state a checkpoint carries.
    ``settings``: what the method was built from (its linear solver resolved)."""

    def __init__(self, physics: DisplacementPhysics, solver: DisplacementMethod, settings: MethodSettings) -> None:
        self.physics, self.solver, self.settings = physics, solver, settings
        self.u, self.contact, self.ops, self.problem = physics.u, physics.contact, physics.ops, physics.problem
        self.diagnostics = physics.diagnostics

    def solve(self, t: float) -> SolveInfo:
        """Solve for u at time t (u holds the previous level as initial guess)."""
        return self.solver.solve(self.problem.begin_level(t))

    # ------------------------------------------------------------------ checkpoints
    def state(self) -> dict[str, np.ndarray]:
        """Vectors carried from one level to the next (the first residual of a level is derived from them), and
        the method's own (newton_condensed's predictor)."""
        return {"F_last": self.problem.F_last.array, "b": self.ops.b.array, **self.solver.state()}

    def scalars(self) -> dict[str, float]:
        """Numbers carried from one level to the next, the method's own included (auto: the level it switched at)."""
        return {"c_norm": self.problem.contact_norm, "reuse": float(self.problem.carried), **self.solver.scalars()}

    def restore_vector(self, name: str, values: np.ndarray) -> None:
        """Set a carried vector (owned values) from a checkpoint."""
        own = {"F_last": self.problem.F_last, "b": self.ops.b}
        if name in own:
            own[name].array[:] = values.ravel()
        else:  # the method's own (state() named it)
            self.solver.restore(name, values)

    def restore_scalars(self, scalars: dict[str, float]) -> None:
        """Continue exactly where a checkpointed run was (the Jacobian is rebuilt at the first solve)."""
        self.problem.resume(bool(scalars["reuse"]), float(scalars["c_norm"]))
        self.solver.restore_scalars({k: v for k, v in scalars.items() if k not in ("c_norm", "reuse")})


def build_mechanics(geo: Geometry, u: fem.Function, material: MaterialConfig, boundaries: tuple[BoundaryConfig, ...],
                    settings: MethodSettings, history: History | None = None, implicit_term=None,
                    body_force: BodyForceConfig | None = None) -> Mechanics:
    """The scene's displacement physics and the method that solves it, chosen once (methods.build_method)."""
    physics = build_physics(geo, u, material, boundaries, settings.contact_rule, history, implicit_term,
                            body_force)
    context = MethodContext(physics.problem, settings, geo.comm, geo, physics.parts, physics.points)
    return Mechanics(physics, build_method(context), settings)
