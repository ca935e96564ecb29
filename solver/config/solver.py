"""[solver]: the displacement method and its tolerances, the damage scheme, linear solvers, quadrature."""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass

from .fields import Ctx, boolean, check_keys, integer, names, need, number, string

METHODS = ("auto", "newton", "newton_energy", "newton_condensed", "penalty_duality", "fixed_point")
# Newton steps on J: any dimension, any linear solver, any memory rule
NEWTON_METHODS = ("auto", "newton", "newton_energy", "newton_condensed")
DAMAGE_SCHEMES = ("explicit", "semi_implicit")
LINEAR = ("auto", "petsc", "cholmod", "mumps", "redundant", "iterative")
_DEGREES = ("quadrature_degree", "damage_quadrature_degree", "contact_quadrature_degree")
CONTACT_POINTS = ("gauss", "nodes")  # the contact term's points on a facet (physics/quadrature.ContactRule)


@dataclass(frozen=True)
class SolverConfig:
    """Solver settings: the displacement method (auto | newton | newton_energy | newton_condensed | penalty_duality |
    fixed_point; auto: Newton until a level fails, newton_condensed from there, solver/solvers/auto.py) with its
    tolerance and iteration limit, the penalty-duality parameter (omega = value / mu), the
    damage scheme (explicit | semi_implicit), the linear solver and quadrature degrees.

    ``contact_points``: where the contact law acts on each contact facet: ``gauss``, the Gauss points of
    ``contact_quadrature_degree``; ``nodes``, u's nodes on the facet with the Newton-Cotes weights (P1: the vertices;
    P2 in 2-D: Simpson's rule), one point per normal dof, so the contact matrix is lumped (``contact_quadrature_degree``
    is then not read). A different discretization of the contact term: its results differ from ``gauss``'s by the
    discretization error (docs/guide/contact.md).

    ``newton_fallback``: a contact level that plain Newton does not solve within ``max_it`` is solved
    again by Newton with an exact line search on the level's energy (solver/solvers/damped_newton.py), with
    up to damped_newton.FALLBACK_IT_FACTOR * max_it iterations (with ``auto``: by newton_condensed, and so are the later
    levels); false: such a level fails at ``max_it``.

    ``linear = "auto"`` is resolved on the mesh and the run's length (linear.choose_linear): in 2-D CHOLMOD's
    sequential Cholesky on one process for the displacement (PETSc's where PETSc lacks SuiteSparse, and for the
    damage), PETSc's redundant on up to 4 ranks, MUMPS beyond; in 3-D MUMPS below
    linear.AUTO_ITERATIVE_DOFS_3D = 60,000 displacement dofs for a run of 20 steps or more, the iterative solver
    for shorter runs from 10,000 dofs and for every run from 60,000 (benchmarks/results/auto_rule.md)."""

    rtol: float = 1e-10
    max_it: int = 25
    linear: str = "auto"
    method: str = "auto"
    penalty_duality_omega: float = 0.5
    damage_scheme: str = "explicit"
    quadrature_degree: int = 0  # 0: from the degrees ([discretization]); resolved when parsed
    damage_quadrature_degree: int = 0
    contact_quadrature_degree: int = 0
    contact_points: str = "gauss"
    petsc_options: tuple[tuple[str, str], ...] = ()
    newton_fallback: bool = True


def parse(ctx: Ctx, t: dict, scene: dict) -> SolverConfig:
    t = check_keys(ctx, "solver", t, names(SolverConfig))
    d = SolverConfig()
    rtol = number(ctx, "solver.rtol", t.get("rtol", d.rtol))
    need(ctx, "solver.rtol", rtol, 0 < rtol < 1, "must be in (0, 1)")
    max_it = integer(ctx, "solver.max_it", t.get("max_it", d.max_it))
    need(ctx, "solver.max_it", max_it, max_it >= 1, "must be >= 1")
    linear = string(ctx, "solver.linear", t.get("linear", d.linear), LINEAR)
    method = string(ctx, "solver.method", t.get("method", d.method), METHODS)
    omega = number(ctx, "solver.penalty_duality_omega", t.get("penalty_duality_omega", d.penalty_duality_omega))
    need(ctx, "solver.penalty_duality_omega", omega, omega > 0, "must be > 0 (omega = value / mu)")
    damage_scheme = string(ctx, "solver.damage_scheme", t.get("damage_scheme", d.damage_scheme), DAMAGE_SCHEMES)
    disc = scene["discretization"]
    auto = {"quadrature_degree": disc.memory_quadrature_degree(),
            "damage_quadrature_degree": 2 * disc.zeta_degree + 2 * (disc.u_degree - 1),
            "contact_quadrature_degree": disc.contact_quadrature_degree()}
    degs = {}
    for key in _DEGREES:
        degs[key] = integer(ctx, f"solver.{key}", t.get(key, auto[key]))
        need(ctx, f"solver.{key}", degs[key], 1 <= degs[key] <= 10, "must be in 1..10")
    has_contact = any(b.role == "contact" for b in scene["boundary"])
    contact_points = string(ctx, "solver.contact_points", t.get("contact_points", d.contact_points), CONTACT_POINTS)
    if contact_points == "nodes" and scene["dim"] == 3 and disc.u_degree == 2:
        # the P2 triangle's nodal (Newton-Cotes) rule weighs its vertices 0: the law would not act there
        raise ctx.fail("solver.contact_points", contact_points, "needs discretization.u_degree = 1 in 3-D "
                       "(P2 triangles have no nodal rule with weight at the vertices); use 'gauss'")
    if linear == "iterative" and method not in NEWTON_METHODS:
        # their loops factor one matrix once and re-solve it many times: a direct solve is what they need
        raise ctx.fail("solver.linear", linear, f"needs solver.method = 'newton' (not {method!r}); "
                       "use a direct solver: auto, petsc, cholmod, mumps or redundant")
    if method not in NEWTON_METHODS and has_contact and scene["dim"] != 2:
        raise ctx.fail("solver.method", method, "available for 2-D meshes only; use 'newton'")
    curved = [b for b in scene["boundary"] if b.role == "contact" and not b.contact_law.piecewise_linear]
    if method == "penalty_duality" and curved:
        # its multiplier step needs the resolvent of p - omega I in closed form, and omega ~ a bound of p'
        raise ctx.fail("solver.method", method, f"does not support law {curved[0].law!r} (boundary.{curved[0].name}): "
                       "p' is unbounded, so no omega fits; use 'newton' or 'fixed_point'")
    if scene["memory"].rule == "trapezoid" and method not in NEWTON_METHODS and has_contact:
        raise ctx.fail("memory.rule", "trapezoid", f"needs solver.method = 'newton' (not {method!r})")
    if damage_scheme == "semi_implicit" and scene["time"].order == 2:
        raise ctx.fail("solver.damage_scheme", damage_scheme, "is first order; time.order = 2 uses its own damage step")
    fallback = boolean(ctx, "solver.newton_fallback", t.get("newton_fallback", d.newton_fallback))
    return SolverConfig(rtol, max_it, linear, method, omega, damage_scheme, **degs, contact_points=contact_points,
                        petsc_options=_petsc_options(ctx, t.get("petsc_options", {})), newton_fallback=fallback)


def _petsc_options(ctx: Ctx, opts) -> tuple[tuple[str, str], ...]:
    if not isinstance(opts, dict):
        raise ctx.fail("solver.petsc_options", opts, "must be a table of PETSc option = value")
    out = []
    for key, val in opts.items():
        if isinstance(val, dict) or isinstance(val, list):
            raise ctx.fail(f"solver.petsc_options.{key}", val, "must be a string, number or boolean")
        if isinstance(val, float) and not math.isfinite(val):
            raise ctx.fail(f"solver.petsc_options.{key}", val, "must be finite")
        sval = ("true" if val else "false") if isinstance(val, bool) else str(val)
        out.append((str(key), sval))
    return tuple(out)


def to_toml(m: SolverConfig) -> dict:
    """The table as written; ``contact_points`` only where it is not the default "gauss", so that a default scene's
    resolved config.toml and checkpoint hash are those of the versions before the key."""
    out = dataclasses.asdict(m)
    out["petsc_options"] = dict(m.petsc_options)
    if m.contact_points == "gauss":
        del out["contact_points"]
    return out
