"""[time]: uniform steps k on [0, T] and the order of the time scheme (docs/model.md §3.4, §3.7).

:class:`TimeScheme` is where the order's choices are made, once: the memory rule, the damage step and the
start-up step. The loader resolves ``memory.rule = "auto"`` with :func:`memory_rule`, the same decision.
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass

from .fields import Ctx, boolean, check_keys, integer, names, need, number

MAX_STEPS = 10_000_000


@dataclass(frozen=True)
class TimeConfig:
    """Uniform steps k on [0, T]; ``order`` 1 is the paper's scheme, 2 the second-order one (CN-AB2 damage,
    trapezoidal memory with an extrapolated current level).

    ``adaptive``: the steps are chosen during the run (docs/model.md §3.9): ``k`` is the first one, each step's
    estimated local time error is kept within ``tolerance`` k / T (so that the errors of all steps add up to at
    most ``tolerance`` in the paper's norm), and steps stay within [``k_min``, ``k_max``] (0: T 1e-9 and T)."""

    T: float = 1.0
    k: float = 0.01
    order: int = 1
    adaptive: bool = False
    tolerance: float = 1e-3
    k_min: float = 0.0
    k_max: float = 0.0

    @property
    def steps(self) -> int:
        """The number of steps (adaptive: of steps of the first one, what sizes the run before it starts)."""
        return int(round(self.T / self.k))

    @property
    def smallest(self) -> float:
        """The smallest step an adaptive run takes."""
        return self.k_min if self.k_min > 0 else 1e-9 * self.T

    @property
    def largest(self) -> float:
        """The largest step an adaptive run takes."""
        return self.k_max if self.k_max > 0 else self.T


# kernels with a recursive history, the only ones a trapezoid fits (tabulated and power ones run as fitted sums of
# exponentials; a power kernel has no g(0), and the memory section refuses it a trapezoid)
PRONY_KERNELS = ("constant", "exponential", "tabulated", "power")


def memory_rule(order: int, kernel: str, rule: str) -> str:
    """The memory sum's rule in time: ``rule`` itself unless ``auto``, which is the left-rectangle sum for order 1
    (and for kernels without a recursion) and the extrapolated trapezoid for order 2 (docs/model.md §3.4, §3.7)."""
    if rule != "auto":
        return rule
    return "trapezoid_extrapolated" if order == 2 and kernel in PRONY_KERNELS else "left"


@dataclass(frozen=True)
class TimeScheme:
    """The time scheme of a scene, decided once from its config (docs/model.md §3.2, §3.4, §3.7).

    ``memory_rule``: the memory sum's rule (left | trapezoid | trapezoid_extrapolated); ``damage_scheme``:
    the damage step (explicit | semi_implicit, order 1's ``solver.damage_scheme``; cnab2 for order 2);
    ``heun_start``: level 1 is Heun's predictor-corrector, since order 2's AB2 source and extrapolated u need
    two past levels (only where there is such a source or extrapolation to correct).
    """

    order: int
    memory_rule: str
    damage_scheme: str
    heun_start: bool

    @classmethod
    def decide(cls, order: int, kernel: str, rule: str, damage: bool, damage_scheme: str) -> TimeScheme:
        """From ``time.order``, ``memory.kernel``, ``memory.rule``, ``damage.enabled``, ``solver.damage_scheme``."""
        resolved = memory_rule(order, kernel, rule)
        extrapolated = kernel in PRONY_KERNELS and resolved == "trapezoid_extrapolated"
        second = order == 2
        return cls(order, resolved, "cnab2" if second else damage_scheme, second and (damage or extrapolated))


def parse(ctx: Ctx, t: dict, scene: dict) -> TimeConfig:
    t = check_keys(ctx, "time", t, names(TimeConfig))
    d = TimeConfig()
    T = number(ctx, "time.T", t.get("T", d.T))
    k = number(ctx, "time.k", t.get("k", d.k))
    need(ctx, "time.T", T, T > 0, "must be > 0")
    need(ctx, "time.k", k, k > 0, "must be > 0")
    need(ctx, "time.k", k, k <= T, f"must be <= time.T = {T}")
    adaptive = boolean(ctx, "time.adaptive", t.get("adaptive", d.adaptive))
    tol = number(ctx, "time.tolerance", t.get("tolerance", d.tolerance))
    need(ctx, "time.tolerance", tol, tol > 0, "must be > 0")
    k_min = number(ctx, "time.k_min", t.get("k_min", d.k_min))
    k_max = number(ctx, "time.k_max", t.get("k_max", d.k_max))
    need(ctx, "time.k_min", k_min, k_min >= 0, "must be >= 0 (0: T 1e-9)")
    need(ctx, "time.k_max", k_max, k_max >= 0, "must be >= 0 (0: T)")
    if not adaptive:
        for key in ("tolerance", "k_min", "k_max"):
            if key in t:
                raise ctx.fail(f"time.{key}", t[key], "applies to adaptive steps only (time.adaptive = true)")
    n = T / k
    if not adaptive and abs(n - round(n)) > 1e-9 * max(1.0, n):
        raise ctx.fail("time.k", k, f"must divide time.T = {T} into a whole number of steps (T/k = {n:.6g})")
    if round(n) > MAX_STEPS:
        raise ctx.fail("time.k", k, f"gives {round(n)} steps; at most {MAX_STEPS} are allowed")
    order = integer(ctx, "time.order", t.get("order", d.order))
    need(ctx, "time.order", order, order in (1, 2), "allowed: 1 (the paper's scheme), 2")
    out = TimeConfig(T, k, order, adaptive, tol, k_min, k_max)
    if adaptive:
        need(ctx, "time.k_min", k_min, out.smallest <= k, f"must be <= time.k = {k}")
        need(ctx, "time.k_max", k_max, out.largest >= k and out.largest <= T, f"must be in [time.k, time.T] = [{k}, {T}]")
    return out


def to_toml(m: TimeConfig) -> dict:
    """The section's keys; the adaptive ones only for an adaptive run (a uniform scene keeps its document)."""
    out = dataclasses.asdict(m)
    if not m.adaptive:
        for key in ("adaptive", "tolerance", "k_min", "k_max"):
            del out[key]
    return out
