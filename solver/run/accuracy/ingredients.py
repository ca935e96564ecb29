"""How much each optional ingredient of the model changes the answer, in the paper's error norm
(docs/guide/accuracy.md, "A model no larger than the tolerance needs").

The memory term, the damage and the truncation Phi_L: the difference, max over levels of ||eps(u - u')|| +
||zeta - zeta'||, between the step-doubling pilot at the coarsest step (the start mesh, the lowest degree) and a
run like it without the ingredient (one more run of N0 steps on the start mesh each). Second order over first: the
same with order 1, scaled from the pilots' step to the chosen one (the first order's error ~ k). P2 over P1: the
difference of the two degrees' t = 0 solves on the chosen mesh (P1 interpolated exactly on P2). These are estimates
on coarse discretizations of a property of the continuous model, not bounds.

With ``accuracy.simplify`` the memory term and the damage (the ingredients a step pays for: 10-20% and 12-30% of
it in the project's bench) are left out, the smallest first, while the changes left out add up to at most
SIMPLIFY_FRACTION of the tolerance; the plan is then made for the simplified scene with that sum taken off the
tolerance, so that the full model's error stays within it (the triangle inequality).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, replace

import numpy as np
from dolfinx import fem
from mpi4py import MPI

from solver.config import Config, from_dict, to_dict
from solver.errors import SolveFailure
from solver.mesh.geometry import Geometry
from solver.run.model import Model

from .solves import PilotRun, pilot_run
from .time_error import norms

SIMPLIFY_FRACTION = 0.1  # of TOL: the most the ingredients left out may change the answer, together
DROPPABLE = ("memory", "damage")  # the ingredients whose leaving out saves a step's time


@dataclass(frozen=True)
class Ingredient:
    """One optional ingredient and how much it changed the answer."""

    name: str  # memory, damage, truncation, order, degree
    change: float  # estimated change of the answer in the paper's norm (nan: not measured)
    how: str  # how it was estimated
    dropped: bool = False  # left out by accuracy.simplify

    def summary(self) -> dict:
        return {"change": self.change, "how": self.how, "dropped": self.dropped}

    def line(self, tol: float) -> str:
        """One line of the run's closing report."""
        share = f"{self.change:.2e} ({self.change / tol:.2g} TOL)" if math.isfinite(self.change) else "not measured"
        return f"{self.name}: changes the answer by {share}, {self.how}" + ("; left out" if self.dropped else "")


def without(cfg: Config, name: str) -> Config:
    """The scene without the ingredient ``name`` (memory, damage, truncation) or at first order (order)."""
    data = to_dict(cfg)
    # the memory rule the loader resolved for the scene's order is resolved again (the planner tries order 2 on the
    # simplified scene; a rule resolved for order 1 would hold it at order 1)
    data["memory"] = {k: v for k, v in data["memory"].items() if k != "rule"}
    if name == "memory":
        data["memory"] = {"kernel": "none"}
    elif name == "damage":
        data["damage"] = {"enabled": False}
    elif name == "truncation":
        data["memory"] = {**data["memory"], "L": 1e300}
    elif name == "order":
        data["time"] = {**data["time"], "order": 1}
    else:
        raise ValueError(f"no ingredient {name!r}")
    return from_dict(data, source=cfg.source)


def present(cfg: Config, order: int) -> list[str]:
    """The scene's optional ingredients a pilot can leave out."""
    out = []
    if cfg.memory.kernel != "none":
        out += ["memory", "truncation"]
    if cfg.damage.enabled:
        out.append("damage")
    if order == 2:
        out.append("order")
    return out


def pilot_difference(ref: PilotRun, other: PilotRun, zeta0: float, comm: MPI.Comm) -> float:
    """max over levels of ||eps(u - u')|| + ||zeta - zeta'|| of two runs on one mesh and space (a run without damage
    has zeta = zeta0)."""
    norm_u, norm_z = norms(ref.model, comm)
    out = 0.0
    for j in range(min(len(ref.t), len(other.t))):
        d = norm_u(ref.u[j] - other.u[j])
        if ref.zeta:
            z = other.zeta[j] if other.zeta else np.full_like(ref.zeta[j], zeta0)
            d += norm_z(ref.zeta[j] - z)
        out = max(out, d)
    return out


def pilot_changes(ref: PilotRun, cfg: Config, comm: MPI.Comm, geo: Geometry, order: int, k0: float,
                  k: float, runs: dict[str, PilotRun] | None = None) -> list[Ingredient]:
    """The changes of memory, truncation, damage and order, each from a run of ``cfg`` (the pilot ``ref``'s scene, at
    step ``k0``) without it on ``geo``; the order's scaled to the chosen step ``k``. ``runs``: filled with the runs
    without each of DROPPABLE (with the indicator: a simplified scene's first pilot, :func:`.time_error.first_pilot`)."""
    out = []
    for name in present(cfg, order):
        try:
            other = pilot_run(without(cfg, name), comm, geo, indicator=runs is not None and name in DROPPABLE)
        except SolveFailure:
            out.append(Ingredient(name, math.nan, "its pilot did not converge"))
            continue
        if runs is not None and name in DROPPABLE:
            runs[name] = other
        d = pilot_difference(ref, other, cfg.damage.zeta0, comm)
        how = f"pilots at k = {k0:g} on the start mesh"
        if name == "order":
            d *= k / k0
            how = f"pilots at k = {k0:g} on the start mesh, times k / {k0:g} (first order)"
        out.append(Ingredient(name, d, how))
    return out


def at_step(changes: list[Ingredient], k0: float, k: float) -> list[Ingredient]:
    """``changes`` measured with the order's scaled to ``k0`` (:func:`pilot_changes` with k = k0), the order's scaled
    to the step ``k`` instead."""
    return [replace(i, change=i.change * k / k0) if i.name == "order" else i for i in changes]


def degree_change(p1: Model, p2: Model, comm: MPI.Comm) -> float:
    """||eps(u_P2 - u_P1)|| of two t = 0 solves on one mesh (u_P1 interpolated on P2's space: exact)."""
    V = p2.u.function_space
    d = fem.Function(V)
    d.interpolate(p1.u)
    d.x.array[:] -= p2.u.x.array
    return norms(p2, comm)[0](d.x.array)


def simplified(changes: list[Ingredient], tol: float) -> tuple[list[Ingredient], float]:
    """The ingredients with ``dropped`` set on those accuracy.simplify leaves out (of DROPPABLE, the smallest change
    first, while their sum stays within SIMPLIFY_FRACTION of ``tol``), and that sum."""
    total, drop = 0.0, set()
    for ing in sorted((i for i in changes if i.name in DROPPABLE and math.isfinite(i.change)), key=lambda i: i.change):
        if total + ing.change > SIMPLIFY_FRACTION * tol:
            break
        total += ing.change
        drop.add(ing.name)
    return [Ingredient(i.name, i.change, i.how, i.name in drop) for i in changes], total
