"""The long-memory integral, kept at quadrature points (docs/model.md §3.1, §3.4).

The scheme's memory sum is a left-rectangle rule,

    M_n = k sum_{m=0}^{n-1} g((n - m) k) H_m,    H_m = zeta_m Phi_L(A eps(u_m)),

evaluated at the quadrature points of the displacement form. For a Prony
kernel g(s) = sum_i c_i exp(-s / tau_i) (tau = inf: the constant kernel) it is
the recursion M_n^i = exp(-k / tau_i) (M_{n-1}^i + k c_i H_{n-1}): no past is
stored. A tabulated or power kernel runs as the sum of exponentials fitted to it at set-up
(:mod:`solver.laws.kernels`), so no kernel keeps the past.

H is the law :class:`solver.laws.memory.MemoryIntegrand`, evaluated at the points by
:mod:`solver.physics.memory_source`. The history is committed once per step, after the step has
converged. The trapezoidal rule (``memory.rule = "trapezoid"``) adds the current level's
(k/2) g(0) H_n, implicit in u_n: :func:`trapezoid_term` gives that term of the displacement
residual, weighted by the history's own ``current_weight``. With
``trapezoid_extrapolated`` (the default of ``time.order = 2``) H_n is evaluated at
u* = 2 u_{n-1} - u_{n-2} instead (:meth:`PronyHistory.extrapolate`): an O(k^3) change per
level that keeps the Jacobian, and its factorization, independent of zeta_n.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
import ufl
from dolfinx import fem
from petsc4py import PETSc

from solver.config import MemoryConfig
from solver.config.memory import FITTED_KERNELS
from solver.laws.kernels import KernelFit
from solver.laws.memory import MemoryIntegrand, truncate
from solver.physics.material import strain
from solver.physics.quadrature import QuadratureRule, all_finite


class History:
    """Base: the memory tensor M (a quadrature function) and its update after a step."""

    M: fem.Function
    extrapolated = False  # True: the current level's term is set by extrapolate() before the displacement solve
    current_weight: fem.Constant | None = None  # the implicit trapezoid's weight of the current level's term
    kernel_fit: KernelFit | None = None  # a tabulated or power kernel's sum of exponentials, its terms and error

    def commit(self, n: int) -> None:
        """Given the converged level n (u_n, zeta_n), form M_{n+1}."""
        raise NotImplementedError

    def set_step(self, k: float, k_prev: float | None) -> None:
        """The next commit forms M_{n+1} over the step k = t_{n+1} - t_n; ``k_prev`` = t_n - t_{n-1} (None at n = 0)."""
        raise NotImplementedError

    def extrapolate(self, u_prev: np.ndarray | None) -> None:
        """The current level's term at u* = 2 u - u_prev (``extrapolated`` histories only)."""
        raise NotImplementedError

    def finite(self) -> bool:
        """Whether M holds no NaN or inf (the stepper's check after each level)."""
        return all_finite(self.M.x.array)

    def state(self) -> dict[str, np.ndarray]:
        """Arrays that define the history, M included (checkpoints write and restore them in place)."""
        raise NotImplementedError


@dataclass(frozen=True)
class SumRule:
    """The quadrature in time of a Prony history M_n = k sum_m g((n-m) k) H_m (docs/model.md §3.4, §3.7).

    ``first_weight``: the weight of H_0 in the recursion (1: left rectangles; 1/2: trapezoid, whose
    current level's term (k/2) g(0) H_n is added apart). ``extrapolated``: that term is H at an
    extrapolated u* = 2 u_{n-1} - u_{n-2}, set before the displacement solve, so the recursion's
    past sum P is kept apart from M (M_n = P_n + (k/2) g(0) H(u*)); otherwise it is implicit in u_n
    (:func:`trapezoid_term`) or absent (left), and the recursion writes M itself.
    """

    name: str
    first_weight: float
    extrapolated: bool = False

    @property
    def implicit(self) -> bool:
        """Whether the current level's term is implicit in u_n (the displacement form carries it)."""
        return self.first_weight != 1.0 and not self.extrapolated


LEFT = SumRule("left", 1.0)
TRAPEZOID = SumRule("trapezoid", 0.5)
TRAPEZOID_EXTRAPOLATED = SumRule("trapezoid_extrapolated", 0.5, extrapolated=True)
SUM_RULES = {r.name: r for r in (LEFT, TRAPEZOID, TRAPEZOID_EXTRAPOLATED)}  # by the TimeScheme's memory_rule


class PronyHistory(History):
    """Prony series (constant kernel: one term with tau = inf), updated recursively.

    ``source`` evaluates H at the rule's points (:class:`solver.physics.memory_source.MemorySource`); with an
    extrapolated rule it should keep two strains (``keep=2``), which :meth:`extrapolate` reads again.
    ``current_weight``: with the implicit trapezoid, the weight (k/2) g(0) of the current level's term as a
    constant of the displacement form (0 at level 0, where M_0 = 0; set by :meth:`commit`); None otherwise.
    """

    def __init__(self, rule: QuadratureRule, source, weights, times, k: float,
                 sum_rule: SumRule = LEFT) -> None:
        self.rule = rule
        self.M = fem.Function(source.Q, name="memory")
        self.H = source
        self.sum_rule = sum_rule
        extrapolated = self.extrapolated = sum_rule.extrapolated
        self.P = np.zeros_like(self.M.x.array) if extrapolated else None
        self._sum: float | None = None  # the sum of M, taken where M was last written (still in cache)
        # a constant, not a number: not compiled into the form
        self.current_weight = fem.Constant(rule.mesh, PETSc.ScalarType(0.0)) if sum_rule.implicit else None
        self.g0 = float(np.sum(weights))
        self.taus = list(times) if times else [math.inf] * len(weights)
        taus = self.taus
        self.weights = np.asarray(weights, dtype=float)
        self.k = math.nan
        self.set_step(k, None)
        # one term: M itself is the term; several: one array per term
        self.terms = [np.zeros_like(self.M.x.array) for _ in taus] if len(taus) > 1 else None
        # several terms: H of a level, then its increment (no temporaries per step); one term needs none
        self._h = np.empty_like(self.M.x.array) if self.terms is not None else None

    def set_step(self, k: float, k_prev: float | None) -> None:
        """Variable steps (docs/model.md §3.9): each term decays by exp(-k/tau) over the step k = t_{n+1} - t_n;
        H_n weighs k (left) or (k_prev + k)/2 (trapezoid); the extrapolation's u* = u_n + (k/k_prev)(u_n - u_{n-1}).
        A uniform step keeps every number of the uniform recursion (the same k, weights and decay)."""
        if k != self.k:
            self.k = k
            self.decay = np.array([math.exp(-k / t) if math.isfinite(t) else 1.0 for t in self.taus])
        self.k_prev = k_prev
        # H_n's weight over k: 1 but for the trapezoid after a change of step
        uneven = self.sum_rule.first_weight != 1.0 and k_prev is not None and k_prev != k
        self.stretch = 0.5 * (k_prev + k) / k if uneven else 1.0
        self.ratio = k / k_prev if k_prev is not None and k_prev != k else 1.0

    def _weight(self, n: int) -> float:
        """H_n's weight in the recursion: k (left; the trapezoid's k/2 at n = 0), (k_prev + k)/2 (trapezoid)."""
        if n == 0:
            return self.sum_rule.first_weight * self.k
        return 0.5 * (self.k_prev + self.k) if self.stretch != 1.0 else self.k

    def commit(self, n: int) -> None:
        half = self.sum_rule.first_weight if n == 0 else 1.0
        if self.current_weight is not None:
            self.current_weight.value = 0.5 * self.k * self.g0
        if self.terms is None:
            m = self.P if self.extrapolated else self.M.x.array
            self.H(m, scale=self._weight(n) * self.weights[0], base=m)  # m += k c H, added by the source in one pass
            if self.decay[0] != 1.0:
                m *= self.decay[0]
            self._written()
            return
        h = self.H(self._h)
        if half != 1.0:
            h *= half
        elif self.stretch != 1.0:
            h *= self.stretch
        total = self.P if self.extrapolated else self.M.x.array
        total[:] = 0.0
        step = np.empty_like(h)
        for term, c, e in zip(self.terms, self.weights, self.decay):
            term += np.multiply(h, self.k * c, out=step)
            term *= e
            total += term
        self._written()

    def extrapolate(self, u_prev: np.ndarray | None) -> None:
        """M_n = P_n + (k/2) g(0) H(u*, zeta), u* = 2 u - u_prev with u the field's values (u_{n-1}); u_prev None:
        u* = u (``extrapolated`` only). u itself is not changed."""
        M, w = self.M.x.array, 0.5 * self.k * self.g0
        if u_prev is None:
            self.H(M, scale=w, base=self.P)
        else:
            self.H.extrapolated(u_prev, M, scale=w, base=self.P, ratio=self.ratio)
        self._written()

    def _written(self) -> None:
        """M was just written: take its sum now, while it is in cache (``finite`` reads it)."""
        with np.errstate(over="ignore", invalid="ignore"):
            self._sum = float(np.add.reduce(self.M.x.array))

    def finite(self) -> bool:
        """Whether M holds no NaN or inf, from the sum taken when this history last wrote M. After :meth:`state`
        (a checkpoint may write M through it) M is summed again, until the next commit."""
        return all_finite(self.M.x.array, self._sum)

    def state(self) -> dict[str, np.ndarray]:
        self._sum = None  # the caller may write the arrays
        out = {"M": self.M.x.array}
        if self.P is not None:
            out["P"] = self.P
        if self.terms is not None:
            out.update({f"M{i}": t for i, t in enumerate(self.terms)})
        return out


class PlaneStrainHistory(History):
    """The in-plane history and the out-of-plane one M_33 (plane strain), committed and checkpointed together.

    M_33 follows the same kernel and rule as M, with H_33 (:class:`OutOfPlaneSource`) as its
    integrand; it enters no equation (sigma_33 is a reaction of the plane-strain constraint)
    and is read by the outputs: sigma_33 = lambda tr eps(u_n) + M_33,n. M, H, the rule and the
    finiteness check are the in-plane history's.
    """

    def __init__(self, main: History, out_of_plane: History) -> None:
        self.main, self.out_of_plane = main, out_of_plane
        self.M33 = out_of_plane.M
        self.extrapolated = main.extrapolated  # History's class default (False) would hide the main one's

    @property
    def M(self) -> fem.Function:
        return self.main.M

    @property
    def H(self):
        return self.main.H

    @property
    def rule(self) -> QuadratureRule:
        return self.main.rule

    @property
    def current_weight(self) -> fem.Constant | None:
        return self.main.current_weight

    @property
    def kernel_fit(self) -> KernelFit | None:
        return self.main.kernel_fit

    def finite(self) -> bool:
        return self.main.finite()

    def commit(self, n: int) -> None:
        self.main.commit(n)
        self.out_of_plane.commit(n)

    def set_step(self, k: float, k_prev: float | None) -> None:
        self.main.set_step(k, k_prev)
        self.out_of_plane.set_step(k, k_prev)

    def extrapolate(self, u_prev: np.ndarray | None) -> None:
        """The extrapolated trapezoid's current term for both, at the same u*."""
        self.main.extrapolate(u_prev)
        self.out_of_plane.extrapolate(u_prev)

    def state(self) -> dict[str, np.ndarray]:
        return {**self.main.state(), **{f"zz_{k}": v for k, v in self.out_of_plane.state().items()}}


def memory_source(u, zeta, A, L: float):
    """H = zeta Phi_L(A eps(u)) for an elasticity map A (UFL); :meth:`MemoryIntegrand.ufl` is the law's own form."""

    return zeta * truncate(A(strain(u)), L)


def make_history(cfg: MemoryConfig, sum_rule: str, rule: QuadratureRule, source, k: float,
                 steps: int) -> History | None:
    """The history for the kernel: None, or the Prony recursion (a tabulated or power kernel's with the sum of
    exponentials fitted to it for this run's lags, :meth:`MemoryConfig.fit`, kept as ``kernel_fit``).

    ``sum_rule``: the rule in time the scene's :class:`solver.config.time.TimeScheme` chose.
    ``source`` evaluates H at the rule's points (:mod:`solver.physics.memory_source`): the quadrature
    space ``Q``, ``source(out, scale, base)`` -> base + scale H and ``extrapolated(u_prev, ...)``.
    """
    if cfg.kernel == "none":
        return None
    if cfg.kernel in ("constant", "exponential"):
        return PronyHistory(rule, source, cfg.weights, cfg.times, k, SUM_RULES[sum_rule])
    if cfg.kernel not in FITTED_KERNELS:
        raise ValueError(f"unknown memory kernel '{cfg.kernel}'")
    time_rule = SUM_RULES[sum_rule]
    fit = cfg.law().prony(k, steps, cfg.kernel_tolerance, zero=time_rule.first_weight != 1.0)
    history = PronyHistory(rule, source, fit.prony.weights, fit.prony.times, k, time_rule)
    history.kernel_fit = fit
    return history


def trapezoid_term(history: PronyHistory, integrand: MemoryIntegrand, zeta):
    """(u, w) -> the implicit trapezoid's current-level term (k/2) g(0) (zeta_n Phi_L(A eps(u_n)), eps(w)) over the
    rule's points, weighted by the history's ``current_weight`` (which the history's commit sets)."""

    if history.current_weight is None:
        rule = history.sum_rule.name if isinstance(history, PronyHistory) else type(history).__name__
        raise ValueError(f"a {rule} history has no implicit current-level term (only the implicit trapezoid's has)")
    weight, dx = history.current_weight, history.rule.dx

    def term(u, w):
        return weight * ufl.inner(integrand.ufl(strain(u), zeta), strain(w)) * dx

    return term
