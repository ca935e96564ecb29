"""Memory kernels g(s) and their exponential sums (docs/model.md §3.4, "Any kernel as a sum of exponentials").

A kernel that is not a Prony series (a table, a power law c s^-alpha) is replaced once, at set-up, by a sum of
exponentials g~(s) = sum_i c_i exp(-s / tau_i) (tau = inf: a constant term), so that the memory sum runs through the
Prony recursion, which stores no past. Each kernel here carries its exact g(s) (:meth:`exact`) and its exponential
sum (:meth:`prony`) side by side; :func:`kernel_error` is the maximum relative difference between the two at the lags
the run evaluates (:func:`run_lags`), and the sum is the one with the fewest terms found whose error is at most the
asked tolerance, within :data:`MAX_TERMS`. A kernel no sum meets is refused with a :class:`KernelFitError` that
says what was reached.

How the sum is built (measured in docs/benchmarks/methods.md, "Kernels as exponential sums"): least squares on the
relative residual over log-spaced time constants, nonnegative (:func:`scipy.optimize.nnls`, best for smooth
mixtures such as s^-alpha) or signed (best where the kernel is itself a short Prony series whose time constants
are not on the grid: a single exponential is not a positive sum of other exponentials), each pruned term by term
while the tolerance holds, then the fewest terms taken.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from functools import lru_cache

import numpy as np

__all__ = ["MAX_TERMS", "ExponentialSum", "KernelFit", "KernelFitError", "PowerKernel", "TabulatedKernel",
           "fit_exponential_sum", "kernel_error", "run_lags"]

MAX_TERMS = 64  # the term budget: at most this many exponentials (each costs one array and one pass per step)
MAX_CHECKED_LAGS = 200_000  # lags checked one by one; longer runs are checked at this many log-spaced lags
_FIT_SAMPLES = 1500  # lags the least-squares problems are set on (log-spaced among the run's)
_DENSITIES = (1, 2, 3, 4, 6, 8, 12, 16)  # time constants per decade tried, fewest first
_EPS = np.finfo(float).eps
_REFINED_TERMS = 6  # the most terms the time constants are moved for


class KernelFitError(ValueError):
    """No exponential sum of at most :data:`MAX_TERMS` terms meets the tolerance; ``reason`` says what was reached."""

    def __init__(self, reason: str) -> None:
        super().__init__(reason)
        self.reason = reason


@dataclass(frozen=True)
class ExponentialSum:
    """g~(s) = sum_i weights[i] exp(-s / times[i]); a time of inf is a constant term."""

    weights: tuple[float, ...]
    times: tuple[float, ...]

    def __call__(self, s: np.ndarray) -> np.ndarray:
        s = np.asarray(s, dtype=float)
        out = np.zeros_like(s)
        for c, tau in zip(self.weights, self.times):
            out += c * (np.exp(-s / tau) if math.isfinite(tau) else 1.0)
        return out

    @property
    def terms(self) -> int:
        return len(self.weights)


@dataclass(frozen=True)
class KernelFit:
    """The exponential sum of a kernel, the maximum relative kernel error it reached at the checked lags, the
    tolerance asked and the lag range [lag_min, lag_max] checked."""

    prony: ExponentialSum
    error: float
    tolerance: float
    lag_min: float
    lag_max: float

    @property
    def terms(self) -> int:
        return self.prony.terms

    def summary(self) -> str:
        """One line for the run's log."""
        return (f"{self.terms} exponential term(s), max relative kernel error {self.error:.2e} "
                f"(tolerance {self.tolerance:.0e}) on lags [{self.lag_min:.4g}, {self.lag_max:.4g}]")


def run_lags(k: float, steps: int, zero: bool = False) -> np.ndarray:
    """The lags at which a run of ``steps`` uniform steps k evaluates its kernel: m k, m = 1..steps (and 0 with
    ``zero``, the trapezoidal rules' current level). Above :data:`MAX_CHECKED_LAGS`, that many log-spaced ones."""
    if steps <= MAX_CHECKED_LAGS:
        m = np.arange(1, steps + 1, dtype=float)
    else:
        m = np.unique(np.round(np.geomspace(1, steps, MAX_CHECKED_LAGS)))
    lags = k * m
    return np.concatenate([[0.0], lags]) if zero else lags


def kernel_error(exact: np.ndarray, approx: np.ndarray) -> float:
    """max |g~ - g| / |g| over the lags (the kernels fitted here are nonzero there)."""
    return float(np.max(np.abs(approx - exact) / np.abs(exact)))


def _basis(s: np.ndarray, times: np.ndarray) -> np.ndarray:
    with np.errstate(divide="ignore"):
        rates = np.where(np.isfinite(times), 1.0 / times, 0.0)
    return np.exp(-np.outer(s, rates))


def _solve(A: np.ndarray, b: np.ndarray, signed: bool) -> np.ndarray:
    from scipy.optimize import nnls  # here, not at import: every scene reads this module, few fit a kernel (24 MiB)

    if signed:
        return np.linalg.lstsq(A, b, rcond=None)[0]
    return nnls(A, b, maxiter=50 * A.shape[1])[0]


def _error(times: np.ndarray, c: np.ndarray, lags: np.ndarray, g: np.ndarray) -> float:
    """The relative error, and a loss of digits to cancellation counted as error (eps sum|c_i e^-s/tau_i| / |g|)."""
    B = _basis(lags, times)
    err = kernel_error(g, B @ c)
    spread = float(np.max((np.abs(B) @ np.abs(c)) / np.abs(g)))
    return max(err, 64 * _EPS * spread)


def _pruned(times: np.ndarray, A: np.ndarray, b: np.ndarray, s: np.ndarray, g_abs: np.ndarray, tol: float,
            signed: bool) -> tuple[np.ndarray, np.ndarray, float]:
    """The fit on ``times`` (coefficients of |g|) and its error at the fitting lags, then terms dropped one by one
    (the smallest contribution first, refitted) while that error stays below tol/2."""
    keep = np.arange(len(times))
    c = _solve(A, b, signed)
    nz = np.abs(c) > 0
    keep, c = keep[nz], c[nz]
    if len(c) == 0:
        return times[:0], c, math.inf
    err = _error(times[keep], c, s, g_abs)
    if err > tol / 2:
        return times[keep], c, err
    while len(keep) > 1:
        size = np.abs(c) * np.max(np.abs(A[:, keep]), axis=0)
        trial = np.delete(keep, int(np.argmin(size)))
        ct = _solve(A[:, trial], b, signed)
        nz = np.abs(ct) > 0
        trial, ct = trial[nz], ct[nz]
        e = _error(times[trial], ct, s, g_abs) if len(ct) else math.inf
        if e > tol / 2:
            break
        keep, c, err = trial, ct, e
    return times[keep], c, err


def _refined(t: np.ndarray, c: np.ndarray, s: np.ndarray, g_abs: np.ndarray, lags: np.ndarray, g: np.ndarray,
             sign: float, tol: float, most: int) -> tuple[np.ndarray, np.ndarray, float] | None:
    """A sum of at most ``most`` terms (and :data:`_REFINED_TERMS`) from (t, c) by moving the time constants (variable
    projection: log tau by nonlinear least squares, the weights by linear least squares at each trial): m = 1, 2, ...
    terms started from the m largest weights; the first m that meets tol at every lag, or None. It finds a short Prony series given
    as a table; it is too slow to pay for smooth mixtures (s^-alpha), which keep the pruned least-squares sum."""
    from scipy.optimize import least_squares  # here, not at import (see _solve)

    w = 1.0 / g_abs
    for m in range(1, min(most, _REFINED_TERMS) + 1):
        start = np.sort(t[np.argsort(np.abs(c))[::-1][:m]])
        const = not np.all(np.isfinite(start))
        x0 = np.log(start[np.isfinite(start)])
        if len(x0) == 0:
            continue

        def weights(x: np.ndarray, const: bool = const) -> tuple[np.ndarray, np.ndarray]:
            times = np.append(np.exp(x), math.inf) if const else np.exp(x)
            B = _basis(s, times) * w[:, None]
            return times, np.linalg.lstsq(B, np.ones(len(s)), rcond=None)[0]

        def residual(x: np.ndarray, weights=weights) -> np.ndarray:
            times, a = weights(x)
            return _basis(s, times) @ a * w - 1.0

        with np.errstate(over="ignore", invalid="ignore", under="ignore"):
            x = least_squares(residual, x0, max_nfev=100 * len(x0), xtol=1e-15, ftol=1e-15, gtol=1e-15).x
        with np.errstate(over="ignore", invalid="ignore"):
            times, a = weights(x)
        if not np.all(np.isfinite(a)):
            continue
        a = a * sign
        err = _error(times, a, lags, g)
        if err <= tol:
            return times, a, err
    return None


def fit_exponential_sum(exact, lags: np.ndarray, tolerance: float, constant_tail: bool = False,
                        also: np.ndarray | None = None, hint: str = "a larger tolerance") -> KernelFit:
    """The exponential sum with the fewest terms found whose maximum relative error against ``exact`` (a function
    of s) at ``lags`` (and at the points ``also``) is at most ``tolerance``, within :data:`MAX_TERMS`; raises
    :class:`KernelFitError` otherwise, whose reason ends with ``hint`` (what to change).

    Time constants log-spaced over [lag_min / 10, 10 lag_max] at 1, 2, 3, ... per decade (and, with
    ``constant_tail``, a constant term); at each density a nonnegative and a signed least-squares fit on the
    relative residual, each pruned; the first density with a fit that meets the tolerance at every lag gives the
    answer (the fewer terms of its two fits).
    """
    lags = np.asarray(lags, dtype=float)
    pos = lags[lags > 0]
    lo, hi = float(pos.min()), float(lags.max())
    if also is not None and len(also):
        lags = np.union1d(lags, np.asarray(also, dtype=float))
    g = np.asarray(exact(lags), dtype=float)
    if not np.all(np.isfinite(g)):
        raise KernelFitError("the kernel is not finite at every lag the run evaluates")
    if np.any(g == 0) or (np.any(g > 0) and np.any(g < 0)):
        raise KernelFitError("the kernel must keep one sign and not vanish at the lags the run evaluates "
                             f"({lags.min():.4g} to {lags.max():.4g}): its error is measured relative to |g|")
    sign = 1.0 if g[0] > 0 else -1.0
    idx = np.unique(np.round(np.geomspace(1, len(lags), min(_FIT_SAMPLES, len(lags))) - 1).astype(int))
    s = lags[idx]
    if lags.min() == 0 and s[0] != 0:
        s = np.concatenate([[0.0], s])
    g_s = np.asarray(exact(s), dtype=float)
    w = 1.0 / np.abs(g_s)
    b = np.ones(len(s))
    best: tuple[np.ndarray, np.ndarray, float] | None = None
    near: tuple[np.ndarray, np.ndarray, float] = (np.empty(0), np.empty(0), math.inf)  # the smallest error reached
    reached = math.inf
    decades = math.log10(hi / lo) + 2
    for density in _DENSITIES:
        times = np.logspace(math.log10(lo) - 1, math.log10(hi) + 1, max(2, int(round(decades * density)) + 1))
        if constant_tail:
            times = np.append(times, math.inf)
        A = _basis(s, times) * w[:, None]
        for signed in (False, True):
            t, c, err = _pruned(times, A, b, s, np.abs(g_s), tolerance, signed)
            if len(c) == 0:
                continue
            c = c * sign
            if err <= tolerance / 2:
                err = _error(t, c, lags, g)
            reached = min(reached, err)
            if err <= tolerance and len(c) <= MAX_TERMS and (best is None or len(c) < len(best[1])):
                best = (t, c, err)
            if err < near[2]:
                near = (t, c, err)
        if best is not None:
            break
        if len(times) > 2 * MAX_TERMS:
            break
    if best is None and len(near[1]) > 1:  # no grid meets it: moving the time constants of the nearest may
        best = _refined(near[0], near[1], s, np.abs(g_s), lags, g, sign, tolerance, len(near[1]))
    if best is None:
        raise KernelFitError(f"no sum of at most {MAX_TERMS} exponentials approximates the kernel to {tolerance:.0e} "
                             f"relative at the lags [{lo:.4g}, {hi:.4g}] the run evaluates (the best reached "
                             f"{reached:.1e}; {hint})")
    t, c, err = best
    fewer = _refined(t, c, s, np.abs(g_s), lags, g, sign, tolerance, len(c) - 1) if len(c) > 1 else None
    if fewer is not None:
        t, c, err = fewer
    order = np.argsort(t)
    prony = ExponentialSum(tuple(float(x) for x in c[order]), tuple(float(x) for x in t[order]))
    return KernelFit(prony, err, tolerance, float(lags.min()), hi)


DENSE_POINTS = 4000  # log-spaced points of [lag_min, lag_max] a power kernel is checked at, between the lags too


@dataclass(frozen=True)
class PowerKernel:
    """g(s) = coefficient s^-exponent, 0 < exponent < 1: weakly singular at s = 0 (no g(0), so left rule only)."""

    coefficient: float
    exponent: float
    hint = "a larger tolerance or fewer decades of lags (a larger k or a shorter T)"

    def __post_init__(self) -> None:
        self.check(self.coefficient, self.exponent)

    @staticmethod
    def check(coefficient: float, exponent: float) -> None:
        """Raise a ValueError naming the parameter unless coefficient != 0 and 0 < exponent < 1."""
        if not (math.isfinite(coefficient) and coefficient != 0):
            raise ValueError("coefficient: must be a nonzero number")
        if not 0 < exponent < 1:
            raise ValueError("exponent: must be strictly between 0 and 1")

    def exact(self, s: np.ndarray) -> np.ndarray:
        s = np.asarray(s, dtype=float)
        with np.errstate(divide="ignore"):
            return self.coefficient * s ** -self.exponent

    def prony(self, k: float, steps: int, tolerance: float, zero: bool = False) -> KernelFit:
        """The exponential sum for a run of ``steps`` steps of k (``zero``: the rule needs g(0): refused)."""
        if zero:
            raise KernelFitError("g(0) is infinite for a power kernel: the trapezoidal rules need it; use the left rule")
        return _cached(self, k, steps, tolerance, False)

    def checked_between(self, lags: np.ndarray) -> np.ndarray:
        """Where the sum is held to g besides the lags: a dense log grid of their range (g is known everywhere)."""
        pos = lags[lags > 0]
        return np.geomspace(pos.min(), pos.max(), DENSE_POINTS)


@dataclass(frozen=True)
class TabulatedKernel:
    """g given by rows (s, g(s)), s from 0 and increasing, linear in between and constant after the last row."""

    table: tuple[tuple[float, float], ...]
    hint = "a finer table, whose kinks between rows limit any smooth sum, or a larger tolerance"

    def exact(self, s: np.ndarray) -> np.ndarray:
        rows = np.asarray(self.table, dtype=float)
        return np.interp(np.asarray(s, dtype=float), rows[:, 0], rows[:, 1])

    def prony(self, k: float, steps: int, tolerance: float, zero: bool = False) -> KernelFit:
        """The exponential sum for a run of ``steps`` steps of k (``zero``: g(0) too, for the trapezoidal rules)."""
        return _cached(self, k, steps, tolerance, zero)

    def checked_between(self, lags: np.ndarray) -> np.ndarray:
        """Where the sum is held to g besides the lags: the rows in their range (the data). Between rows the table
        is an interpolation whose kinks no smooth sum follows; a run with uniform steps never reads it there
        unless its lags fall between rows, and then the lags themselves are checked."""
        rows = np.asarray(self.table, dtype=float)[:, 0]
        return rows[(rows >= lags.min()) & (rows <= lags.max())]


@lru_cache(maxsize=32)
def _cached(kernel: PowerKernel | TabulatedKernel, k: float, steps: int, tolerance: float, zero: bool) -> KernelFit:
    """One fit per kernel and run (the scene's check and the model's history ask for the same one)."""
    lags = run_lags(k, steps, zero)
    return fit_exponential_sum(kernel.exact, lags, tolerance, constant_tail=isinstance(kernel, TabulatedKernel),
                               also=kernel.checked_between(lags), hint=kernel.hint)
