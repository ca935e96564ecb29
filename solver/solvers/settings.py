"""The solver settings each part uses, made once from the scene's ``[solver]`` when the model is built.

``SolverConfig`` is the scene's table as written (``linear = "auto"`` stays "auto" there: the restart's hash reads
it); :class:`MethodSettings` holds what the methods read, with the linear solver already resolved
(linear.choose_linear). Each part gets its own small object: Newton's test and iteration limit
(:class:`NewtonSettings`), the linear solver (:class:`LinearSettings`), the fixed-point iterations
(:class:`PointIterationSettings`). The Newton tolerance ``rtol`` is read from the scene once, here.
"""

from __future__ import annotations

from dataclasses import dataclass

from solver.config import SolverConfig
from solver.physics.quadrature import ContactRule


@dataclass(frozen=True)
class LinearSettings:
    """The linear solver of the displacement: ``kind`` resolved (petsc | redundant | mumps | iterative), and the
    scene's PETSc options (full names, e.g. ``mech_ksp_type``)."""

    kind: str
    petsc_options: tuple[tuple[str, str], ...] = ()

    @property
    def iterative(self) -> bool:
        return self.kind == "iterative"


@dataclass(frozen=True)
class NewtonSettings:
    """Newton's test and limits: ||F|| <= rtol * scale or a step below rtol ||u|| (newton.NewtonTest), at most
    ``max_it`` iterations; ``fallback``: a failed level may go to the damped fallback (``solver.newton_fallback``);
    ``contact_near_nullspace``: the iterative path's near-nullspace without the rigid motions' normal component on
    Gamma_C (False: the plain rigid motions; newton.contact_normals)."""

    rtol: float = 1e-10
    max_it: int = 25
    fallback: bool = True
    contact_near_nullspace: bool = True


@dataclass(frozen=True)
class PointIterationSettings:
    """The fixed-point methods' tolerance (||F|| <= rtol * scale) and iteration limit, penalty-duality's omega
    factor (omega = value / mu) and the contact rule of its penalty matrix (a Gauss degree or a ContactRule)."""

    rtol: float = 1e-10
    max_it: int = 25
    penalty_duality_omega: float = 0.5
    contact_rule: int | ContactRule = 1


@dataclass(frozen=True)
class MethodSettings:
    """What the displacement method is built from: its name (``solver.method``) and each part's settings."""

    method: str
    linear: LinearSettings
    newton: NewtonSettings
    points: PointIterationSettings
    contact_rule: int | ContactRule  # the contact term's rule (ContactRule), or a Gauss degree

    @classmethod
    def from_config(cls, cfg: SolverConfig, linear: str, contact_near_nullspace: bool = True,
                    u_degree: int = 1) -> MethodSettings:
        """The settings of a scene's ``[solver]`` with ``linear``, the linear solver its ``linear`` resolves to, for u
        of ``u_degree`` (the contact rule's nodes)."""
        rule = ContactRule.from_solver(cfg, u_degree)
        return cls(
            method=cfg.method,
            linear=LinearSettings(linear, cfg.petsc_options),
            newton=NewtonSettings(cfg.rtol, cfg.max_it, cfg.newton_fallback, contact_near_nullspace),
            points=PointIterationSettings(cfg.rtol, cfg.max_it, cfg.penalty_duality_omega, rule),
            contact_rule=rule,
        )
