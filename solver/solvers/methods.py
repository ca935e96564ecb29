"""The displacement methods (``solver.method``) as a registry: name -> what the method requires and what is built
instead where it does not apply (docs/model.md §4).

The method is chosen once, when the model is built (:func:`build_method`): a method whose requirement fails is
replaced by its ``instead``, and so on, so every built method applies to its problem and its ``solve`` only solves.

- ``newton``: semismooth Newton with the damped fallback (newton.py, damped_newton.py); any problem.
- ``newton_energy``: Newton with an exact line search on the level's energy (energy_newton.py); requires an energy
  (contact without the implicit memory term), else ``newton``.
- ``newton_condensed``: the levels solved on the contact dofs (condensed.py); requires an energy, a piecewise
  linear law, a direct linear solver and few contact dofs (condensed.applies), else ``newton_energy``.
- ``auto``: Newton, and from the first level it does not solve, ``newton_condensed`` as resolved above (auto.py).
- ``fixed_point``, ``penalty_duality``: iterations on the contact forces with one factored matrix
  (fixed_point.py); require the contact term at its points (2-D).

A problem without contact is linear (or the memory term's Newton): the method is ``newton``.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from functools import cached_property

import numpy as np
from mpi4py import MPI

from solver.config import BoundaryConfig
from solver.errors import ConfigError
from solver.mesh.geometry import Geometry
from solver.physics.contact_points import ContactPoints
from solver.physics.displacement import DisplacementProblem
from solver.solvers.auto import NEWTON_ITERATIONS, AutoSolver
from solver.solvers.condensed import CondensedNewtonSolver, applies
from solver.solvers.contact_dofs import ContactDofs
from solver.solvers.damped_newton import has_energy
from solver.solvers.energy_newton import EnergyNewtonSolver
from solver.solvers.fixed_point import FixedPointSolver, PenaltyDualitySolver
from solver.solvers.method import DisplacementMethod
from solver.solvers.newton import NewtonCore, NewtonSolver
from solver.solvers.settings import MethodSettings


@dataclass(frozen=True)
class MethodContext:
    """What a method is built on: the level problem, the settings, the mesh's contact parts and (2-D) the contact
    term at its points."""

    problem: DisplacementProblem
    settings: MethodSettings
    comm: MPI.Comm
    geo: Geometry
    parts: tuple[BoundaryConfig, ...]
    points: ContactPoints | None

    @cached_property
    def contact_dofs(self) -> ContactDofs:
        """The free dofs of the contact facets (newton_condensed's B). Collective."""
        facets = np.concatenate([self.geo.facets(p.name) for p in self.parts])
        return ContactDofs(self.problem.u, facets, self.geo.dim - 1, self.problem.bcs, self.comm)


@dataclass(frozen=True)
class MethodEntry:
    """A method of the registry: how it is built, what it requires, and the method built ``instead`` where the
    requirement fails (None: nothing; the scene check refuses such a scene)."""

    build: Callable[[MethodContext], DisplacementMethod]
    requires: Callable[[MethodContext], bool] = lambda ctx: True
    instead: str | None = None


def _core(ctx: MethodContext, test_max_it: int | None = None) -> NewtonCore:
    return NewtonCore(ctx.problem, ctx.settings.newton, ctx.settings.linear, ctx.comm, test_max_it)


def _condensed_on(ctx: MethodContext, core: NewtonCore) -> CondensedNewtonSolver:
    return CondensedNewtonSolver(EnergyNewtonSolver(core), ctx.contact_dofs, ctx.settings.linear, ctx.points)


def _newton(ctx: MethodContext) -> NewtonSolver:
    return NewtonSolver(_core(ctx), ctx.settings.newton.fallback)


def _newton_energy(ctx: MethodContext) -> EnergyNewtonSolver:
    return EnergyNewtonSolver(_core(ctx))


def _newton_condensed(ctx: MethodContext) -> CondensedNewtonSolver:
    return _condensed_on(ctx, _core(ctx))


# the methods auto hands a failed level over to, built on Newton's core (its SNES's KSP)
TAKEOVERS: dict[str, Callable[[MethodContext, NewtonCore], DisplacementMethod]] = {
    "newton_energy": lambda ctx, core: EnergyNewtonSolver(core),
    "newton_condensed": _condensed_on,
}


def _auto(ctx: MethodContext) -> AutoSolver:
    """Newton with at most NEWTON_ITERATIONS iterations a level and no fallback, handing over to newton_condensed
    as resolved; Newton alone where nothing can take over (no energy, or ``solver.newton_fallback = false``)."""
    takeover = resolve("newton_condensed", ctx) if ctx.settings.newton.fallback else "newton"
    if takeover not in TAKEOVERS:
        return AutoSolver(_newton(ctx), None)
    core = _core(ctx, min(ctx.settings.newton.max_it, NEWTON_ITERATIONS))
    return AutoSolver(NewtonSolver(core, fallback=False), TAKEOVERS[takeover](ctx, core))


def _fixed_point(ctx: MethodContext) -> FixedPointSolver:
    return FixedPointSolver(ctx.problem, ctx.points, ctx.settings.points, ctx.settings.linear, ctx.comm)


def _penalty_duality(ctx: MethodContext) -> PenaltyDualitySolver:
    return PenaltyDualitySolver(ctx.problem, ctx.points, ctx.settings.points, ctx.settings.linear, ctx.comm, ctx.geo,
                                ctx.parts)


def _has_energy(ctx: MethodContext) -> bool:
    return has_energy(ctx.problem)


def _condensation_applies(ctx: MethodContext) -> bool:
    return has_energy(ctx.problem) and applies(ctx.problem, ctx.settings.linear, ctx.contact_dofs.m)


def _points_2d(ctx: MethodContext) -> bool:
    return ctx.points is not None


# name -> (build, requires, instead): one line a method
METHODS: dict[str, MethodEntry] = {
    "newton": MethodEntry(_newton),
    "newton_energy": MethodEntry(_newton_energy, _has_energy, "newton"),
    "newton_condensed": MethodEntry(_newton_condensed, _condensation_applies, "newton_energy"),
    "auto": MethodEntry(_auto),
    "fixed_point": MethodEntry(_fixed_point, _points_2d),
    "penalty_duality": MethodEntry(_penalty_duality, _points_2d),
}


def resolve(name: str, ctx: MethodContext) -> str:
    """The method built for ``name`` on ``ctx``: ``name`` where it applies, else its ``instead``, and so on."""
    entry = METHODS[name]
    while not entry.requires(ctx):
        if entry.instead is None:
            raise ConfigError(key="solver.method", value=name, allowed="does not apply to this problem (it needs the "
                              "contact term at its points: a 2-D mesh) and has no method instead")
        name = entry.instead
        entry = METHODS[name]
    return name


def build_method(ctx: MethodContext) -> DisplacementMethod:
    """The scene's method on ``ctx`` (``newton`` without contact), chosen once."""
    name = ctx.settings.method if ctx.problem.contact is not None else "newton"
    return METHODS[resolve(name, ctx)].build(ctx)
