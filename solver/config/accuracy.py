"""[accuracy]: a tolerance on the paper's error norm; the solver then picks degree, mesh and step (solver/run/accuracy/).

With ``tolerance`` set, the scene's ``mesh.nx``/``ny``/``nz`` (built-in meshes), ``time.k``,
``discretization.u_degree`` and ``time.order`` are chosen by the solver; the resolved
scene written with the results records what it chose.
"""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass

from .discretization import DEGREES
from .fields import Ctx, boolean, check_keys, integer, names, need, number, string

TIME_MODES = ("uniform", "adaptive")  # accuracy.time: how the plan's step is chosen


@dataclass(frozen=True)
class AccuracyConfig:
    """``tolerance``: bound on max over levels of ||eps(u - u_exact)|| + ||zeta - zeta_exact|| (absolute; with
    ``relative``, times ||eps(u_0)||). ``space_share`` of it goes to the mesh, the rest to the step; ``theta``
    is the Dörfler fraction; ``degrees`` the displacement degrees the solver may choose from; ``simplify`` leaves
    out the memory term and the damage where they change the answer by little (solver/run/accuracy/ingredients.py);
    ``time`` is how the step is chosen: ``uniform`` (one step for the run, by step doubling on pilot runs) or
    ``adaptive`` (the run-time step controller, ``time.adaptive``, with the time's share as ``time.tolerance``)."""

    tolerance: float | None = None
    relative: bool = False
    space_share: float = 0.5
    theta: float = 0.5
    max_dofs: int = 2_000_000
    degrees: tuple[int, ...] = DEGREES
    simplify: bool = False
    time: str = "uniform"

    @property
    def enabled(self) -> bool:
        return self.tolerance is not None


def parse(ctx: Ctx, t: dict, scene: dict) -> AccuracyConfig:
    t = check_keys(ctx, "accuracy", t, names(AccuracyConfig))
    d = AccuracyConfig()
    tol = t.get("tolerance", d.tolerance)
    if tol is not None:
        tol = tolerance(ctx, "accuracy.tolerance", tol)
    relative = boolean(ctx, "accuracy.relative", t.get("relative", d.relative))
    share = number(ctx, "accuracy.space_share", t.get("space_share", d.space_share))
    need(ctx, "accuracy.space_share", share, 0.0 < share < 1.0, "must be strictly between 0 and 1")
    theta = number(ctx, "accuracy.theta", t.get("theta", d.theta))
    need(ctx, "accuracy.theta", theta, 0.0 < theta < 1.0, "must be strictly between 0 and 1")
    max_dofs = integer(ctx, "accuracy.max_dofs", t.get("max_dofs", d.max_dofs))
    need(ctx, "accuracy.max_dofs", max_dofs, max_dofs > 0, "must be > 0")
    raw = t.get("degrees", list(d.degrees))
    if not isinstance(raw, list) or not raw:
        raise ctx.fail("accuracy.degrees", raw, "must be a non-empty list of degrees from 1, 2")
    degrees = tuple(sorted({integer(ctx, "accuracy.degrees", x) for x in raw}))
    need(ctx, "accuracy.degrees", raw, set(degrees) <= set(DEGREES), "allowed: a list of degrees from 1, 2")
    simplify = boolean(ctx, "accuracy.simplify", t.get("simplify", d.simplify))
    mode = string(ctx, "accuracy.time", t.get("time", d.time), TIME_MODES)
    return AccuracyConfig(tol, relative, share, theta, max_dofs, degrees, simplify, mode)


def tolerance(ctx: Ctx, key: str, v) -> float:
    """A tolerance: a finite number strictly between 0 and 1."""
    if isinstance(v, float) and math.isnan(v):
        raise ctx.fail(key, v, "must be a number strictly between 0 and 1 (not NaN)")
    v = number(ctx, key, v)
    need(ctx, key, v, 0.0 < v < 1.0, "must be strictly between 0 and 1")
    return v


def to_toml(m: AccuracyConfig) -> dict:
    out = dataclasses.asdict(m)
    if m.tolerance is None:
        out.pop("tolerance")
    return out
