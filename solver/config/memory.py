"""[memory]: the kernel of the long-memory term and its quadrature rule in time (docs/model.md §2, §3.4)."""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from solver.errors import ConfigError
from solver.laws.kernels import KernelFit, KernelFitError, PowerKernel, TabulatedKernel
from solver.laws.memory import MemoryIntegrand

from .fields import Ctx, check_keys, names, need, number, string, vector
from .tables import as_array, given_as_file, inline, read_csv, row_error, rows_given
from .time import PRONY_KERNELS, memory_rule

KERNELS = ("none", "constant", "exponential", "tabulated", "power")
RULES = ("auto", "left", "trapezoid", "trapezoid_extrapolated")
SECOND_ORDER_RULES = ("trapezoid", "trapezoid_extrapolated")
FITTED_KERNELS = ("tabulated", "power")  # replaced at set-up by a sum of exponentials (solver.laws.kernels)
_USES = {"none": (), "constant": ("weights",), "exponential": ("weights", "times"),
         "tabulated": ("table", "kernel_tolerance"), "power": ("coefficient", "exponent", "kernel_tolerance")}
_OPTIONAL = ("weights", "times", "table", "coefficient", "exponent", "kernel_tolerance")


@dataclass(frozen=True)
class MemoryConfig:
    """Kernel of G(t-s, eps, zeta) = zeta(s) g(t-s) Phi_L(A eps(u(s))).

    ``constant``: g = weights[0]; ``exponential``: g(s) = sum_i weights[i]
    exp(-s/times[i]) (a Prony series); ``tabulated``: g given by ``table``
    rows [s, g(s)], linear in between; ``power``: g(s) = coefficient s^-exponent, 0 < exponent < 1;
    ``none``: no memory. A tabulated or power kernel runs as the sum of exponentials :meth:`fit` finds, to
    ``kernel_tolerance`` relative at the lags the run evaluates (no past is stored).
    ``rule``: ``left``, the paper's left-rectangle sum; ``trapezoid``, the trapezoidal rule implicit
    in the current level (Newton only, one factorization per step); ``trapezoid_extrapolated``, the
    trapezoidal rule with the current level's u extrapolated from the two before (explicit: no
    refactorization); ``auto``: left for ``time.order = 1``, trapezoid_extrapolated for 2
    (:func:`solver.config.time.memory_rule`, resolved by the loader).
    """

    kernel: str = "constant"
    weights: tuple[float, ...] = (1.0,)
    times: tuple[float, ...] = ()
    table: tuple[tuple[float, float], ...] = ()
    coefficient: float = 1.0
    exponent: float = 0.5
    kernel_tolerance: float = 1e-8
    L: float = 1000.0
    rule: str = "auto"

    def law(self) -> PowerKernel | TabulatedKernel:
        """The kernel law of a tabulated or power kernel (:mod:`solver.laws.kernels`)."""
        if self.kernel == "power":
            return PowerKernel(self.coefficient, self.exponent)
        if self.kernel == "tabulated":
            return TabulatedKernel(self.table)
        raise ValueError(f"kernel '{self.kernel}' is a Prony series already")

    def fit(self, k: float, steps: int) -> KernelFit:
        """The sum of exponentials that replaces a tabulated or power kernel in a run of ``steps`` steps of k
        (cached: the scene's check and the model's history share it). Raises KernelFitError."""
        return self.law().prony(k, steps, self.kernel_tolerance, zero=self.rule in SECOND_ORDER_RULES)


def parse(ctx: Ctx, t: dict, scene: dict) -> MemoryConfig:
    t = check_keys(ctx, "memory", t, names(MemoryConfig))
    d = MemoryConfig()
    kernel = string(ctx, "memory.kernel", t.get("kernel", d.kernel), KERNELS)
    rule = string(ctx, "memory.rule", t.get("rule", d.rule), RULES)
    order = scene["time"].order
    rule = memory_rule(order, kernel, rule)
    if rule in SECOND_ORDER_RULES and kernel not in PRONY_KERNELS:
        raise ctx.fail("memory.rule", rule, "the trapezoidal rules are for constant, exponential and tabulated "
                       "kernels")
    if rule in SECOND_ORDER_RULES and kernel == "power":
        raise ctx.fail("memory.rule", rule, "the trapezoidal rules need g(0), which is infinite for a power kernel: "
                       "use rule = 'left' (time.order = 1)")
    if scene["time"].adaptive and kernel in ("tabulated", "power"):
        raise ctx.fail("memory.kernel", kernel, "adaptive steps (time.adaptive) need a constant or exponential kernel "
                       "(a fitted kernel's error is checked at the lags of uniform steps)")
    if order == 1 and rule == "trapezoid_extrapolated" and kernel != "none":
        raise ctx.fail("memory.rule", rule, "the extrapolated trapezoid is time.order = 2's rule (its current term is taken "
                       "at u extrapolated from two past levels): with time.order = 1 use 'left' or 'trapezoid'")
    if order == 2 and rule == "left" and kernel != "none":
        raise ctx.fail("memory.rule", rule, "time.order = 2 needs a second-order rule: trapezoid or trapezoid_extrapolated")
    L = number(ctx, "memory.L", t.get("L", d.L))
    try:  # the law checks its own parameter
        MemoryIntegrand.check_truncation(L)
    except ConfigError as exc:
        raise ctx.fail(f"memory.{exc.key}", exc.value, exc.allowed) from None
    for key in _OPTIONAL:
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
        table = _table(ctx, t.get("table", "<missing>"), scene["base"])
    coefficient, exponent = d.coefficient, d.exponent
    if kernel == "power":
        coefficient = number(ctx, "memory.coefficient", t.get("coefficient", d.coefficient))
        exponent = number(ctx, "memory.exponent", t.get("exponent", d.exponent))
        try:  # the law checks its own parameters
            PowerKernel.check(coefficient, exponent)
        except ValueError as exc:
            key, allowed = str(exc).split(": ", 1)
            raise ctx.fail(f"memory.{key}", coefficient if key == "coefficient" else exponent, allowed) from None
    tol = number(ctx, "memory.kernel_tolerance", t.get("kernel_tolerance", d.kernel_tolerance))
    need(ctx, "memory.kernel_tolerance", tol, 1e-14 <= tol < 1, "must be in [1e-14, 1)")
    cfg = MemoryConfig(kernel, weights, times, table, coefficient, exponent, tol, L, rule)
    if kernel in FITTED_KERNELS:
        tm = scene["time"]
        try:  # refused here, with the scene's source, rather than when the model is built
            cfg.fit(tm.k, tm.steps)
        except KernelFitError as exc:
            raise ctx.fail("memory.kernel_tolerance", tol, exc.reason) from None
    return cfg


def _table(ctx: Ctx, v: object, base: Path) -> tuple[tuple[float, float], ...]:
    """Rows [s, g(s)] (inline or {file, columns}), at least two, s from 0 increasing strictly."""
    key = "memory.table"
    if given_as_file(v):
        table = read_csv(ctx, key, v, base, ("s", "g"))
    else:
        if not rows_given(v):
            raise ctx.fail(key, v, "needs at least two rows [s, g(s)], or {file = 'kernel.csv', columns = [s, g]}")
        table = inline(ctx, key, v, 2, "[s, g(s)]")
    if len(table) < 2:
        raise ctx.fail(key, v if not given_as_file(v) else f"{len(table)} row", "needs at least two rows [s, g(s)]")
    s = as_array(table)[:, 0]
    if s[0] != 0:
        raise row_error(ctx, key, table, 0, float(s[0]), "s must start at 0 and increase strictly")
    down = np.flatnonzero(s[1:] <= s[:-1])
    if len(down):
        i = int(down[0]) + 1
        raise row_error(ctx, key, table, i, [float(s[i - 1]), float(s[i])], "s must start at 0 and increase strictly")
    return table  # type: ignore[return-value]


def to_toml(m: MemoryConfig) -> dict:
    out = {f.name: getattr(m, f.name) for f in dataclasses.fields(m)}  # the table as it is (a file's: a DataTable)
    for key in _OPTIONAL:
        if key not in _USES[m.kernel]:
            out.pop(key)
    return out
