"""[memory]: the kernel of the long-memory term and its quadrature rule in time (docs/model.md §2, §3.4)."""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass

from .fields import Ctx, check_keys, names, need, number, string, vector

KERNELS = ("none", "constant", "exponential", "tabulated")
RULES = ("left", "trapezoid")
_USES = {"none": (), "constant": ("weights",), "exponential": ("weights", "times"), "tabulated": ("table",)}


@dataclass(frozen=True)
class MemoryConfig:
    """Kernel of G(t-s, eps, zeta) = zeta(s) g(t-s) Phi_L(A eps(u(s))).

    ``constant``: g = weights[0]; ``exponential``: g(s) = sum_i weights[i]
    exp(-s/times[i]) (a Prony series); ``tabulated``: g given by ``table``
    rows [s, g(s)], linear in between (keeps the full past); ``none``: no memory.
    ``rule``: the paper's left-rectangle sum, or the trapezoidal rule (implicit in the
    current level: Newton only, one factorization per step).
    """

    kernel: str = "constant"
    weights: tuple[float, ...] = (1.0,)
    times: tuple[float, ...] = ()
    table: tuple[tuple[float, float], ...] = ()
    L: float = 1000.0
    rule: str = "left"


def parse(ctx: Ctx, t: dict, scene: dict) -> MemoryConfig:
    t = check_keys(ctx, "memory", t, names(MemoryConfig))
    d = MemoryConfig()
    kernel = string(ctx, "memory.kernel", t.get("kernel", d.kernel), KERNELS)
    rule = string(ctx, "memory.rule", t.get("rule", d.rule), RULES)
    if rule == "trapezoid" and kernel not in ("constant", "exponential"):
        raise ctx.fail("memory.rule", rule, "the trapezoidal rule is for constant and exponential kernels")
    L = number(ctx, "memory.L", t.get("L", d.L))
    need(ctx, "memory.L", L, L > 0, "must be > 0")
    for key in ("weights", "times", "table"):
        if key in t and key not in _USES[kernel]:
            raise ctx.fail(f"memory.{key}", t[key], f"not used by kernel '{kernel}'")
    weights: tuple[float, ...] = ()
    times: tuple[float, ...] = ()
    table: tuple[tuple[float, float], ...] = ()
    if kernel == "constant":
        weights = vector(ctx, "memory.weights", t.get("weights", [1.0]), 1)
    elif kernel == "exponential":
        for key in ("weights", "times"):
            if key not in t:
                raise ctx.fail(f"memory.{key}", "<missing>", "an exponential kernel needs weights and times")
        weights = vector(ctx, "memory.weights", t["weights"])
        times = vector(ctx, "memory.times", t["times"], len(weights))
        for i, tau in enumerate(times):
            need(ctx, f"memory.times[{i}]", tau, tau > 0, "time constants must be > 0")
    elif kernel == "tabulated":
        if "table" not in t or not isinstance(t["table"], list) or len(t["table"]) < 2:
            raise ctx.fail("memory.table", t.get("table", "<missing>"), "needs at least two rows [s, g(s)]")
        table = tuple(vector(ctx, f"memory.table[{i}]", r, 2) for i, r in enumerate(t["table"]))  # type: ignore[misc]
        s = [r[0] for r in table]
        if s[0] != 0 or any(b <= a for a, b in zip(s, s[1:])):
            raise ctx.fail("memory.table", s, "s must start at 0 and increase strictly")
    return MemoryConfig(kernel, weights, times, table, L, rule)


def to_toml(m: MemoryConfig) -> dict:
    out = dataclasses.asdict(m)
    for key in ("weights", "times", "table"):
        if key not in _USES[m.kernel]:
            out.pop(key)
    return out
