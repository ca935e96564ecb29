"""[time]: uniform steps k on [0, T] and the order of the time scheme (docs/model.md §3.4, §3.7)."""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass

from .fields import Ctx, check_keys, integer, names, need, number

MAX_STEPS = 10_000_000


@dataclass(frozen=True)
class TimeConfig:
    """Uniform steps k on [0, T]; ``order`` 1 is the paper's scheme, 2 the second-order one (CN-AB2 damage,
    trapezoidal memory with an extrapolated current level)."""

    T: float = 1.0
    k: float = 0.01
    order: int = 1

    @property
    def steps(self) -> int:
        return int(round(self.T / self.k))


def parse(ctx: Ctx, t: dict, scene: dict) -> TimeConfig:
    t = check_keys(ctx, "time", t, names(TimeConfig))
    d = TimeConfig()
    T = number(ctx, "time.T", t.get("T", d.T))
    k = number(ctx, "time.k", t.get("k", d.k))
    need(ctx, "time.T", T, T > 0, "must be > 0")
    need(ctx, "time.k", k, k > 0, "must be > 0")
    need(ctx, "time.k", k, k <= T, f"must be <= time.T = {T}")
    n = T / k
    if abs(n - round(n)) > 1e-9 * max(1.0, n):
        raise ctx.fail("time.k", k, f"must divide time.T = {T} into a whole number of steps (T/k = {n:.6g})")
    if round(n) > MAX_STEPS:
        raise ctx.fail("time.k", k, f"gives {round(n)} steps; at most {MAX_STEPS} are allowed")
    order = integer(ctx, "time.order", t.get("order", d.order))
    need(ctx, "time.order", order, order in (1, 2), "allowed: 1 (the paper's scheme), 2")
    return TimeConfig(T, k, order)


def to_toml(m: TimeConfig) -> dict:
    return dataclasses.asdict(m)
