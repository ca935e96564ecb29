"""The normal-compliance laws p of -sigma_nu = p(u_nu - g) (docs/model.md §1, §3.3): one class a law.

Each law is a frozen dataclass whose fields are its scene keys (``[boundary.NAME]``: ``mu``, ``coefficient``, ...)
and carries side by side

- :meth:`ContactLaw.parse`: reading and validating its keys from a scene's table (the errors name the key);
- :meth:`ContactLaw.ufl`: p(r) as the UFL expression the contact forms integrate;
- :meth:`ContactLaw.pressure` and :meth:`ContactLaw.slope`: p(r) and p'(r) at many points (numpy, vectorised);
- :meth:`ContactLaw.inverse`: the r where p(r) reaches a pressure (the diagnostics' allowed penetration);
- :attr:`ContactLaw.kinks`, :attr:`ContactLaw.piecewise_linear`, :attr:`ContactLaw.stiffness`.

Piecewise linear laws (:class:`PiecewiseLinearLaw`) are sums of ramps p(r) = sum_j s_j (r - k_j)_+ with k_0 = 0;
the condensed solver's exact line search and the penalty-duality resolvent work on that form.

:data:`CONTACT_LAWS` maps a scene's ``law`` name to its class: adding a law is one class and one line there
(docs/developer/adding-a-law.md); ``tests/laws/test_contact.py`` then checks it.
"""

from __future__ import annotations

import dataclasses
from abc import ABC, abstractmethod
from collections.abc import Callable, Iterable, Iterator
from dataclasses import dataclass
from typing import Any, ClassVar, Protocol

import numpy as np
import ufl

from solver.laws.constants import constant


class LawTable(Protocol):
    """A scene's contact table as a law reads it (config implements it; errors name ``boundary.NAME.key``)."""

    def given(self, key: str) -> bool:
        """Whether the table has the key."""

    def number(self, key: str, default: float | None = None) -> float:
        """The key's value (or ``default`` when absent), a finite number, else a typed config error."""

    def fail(self, key: str, value: Any, allowed: str) -> Exception:
        """The typed config error for the key, its value and what is allowed."""


def _need(table: LawTable, key: str, value: float, ok: bool, allowed: str) -> None:
    if not ok:
        raise table.fail(key, value, allowed)


@dataclass(frozen=True)
class ContactLaw(ABC):
    """p(r) of one law with its parameters (the dataclass fields, named as the scene keys)."""

    name: ClassVar[str]
    piecewise_linear: ClassVar[bool] = False

    @classmethod
    def keys(cls) -> tuple[str, ...]:
        """The law's scene keys, in the order its errors list them."""
        return tuple(f.name for f in dataclasses.fields(cls))

    def parameters(self) -> dict[str, float]:
        """The law's scene keys and values."""
        return {key: getattr(self, key) for key in self.keys()}

    @classmethod
    @abstractmethod
    def parse(cls, table: LawTable) -> ContactLaw:
        """The law of a scene's contact table, its values validated."""

    @classmethod
    @abstractmethod
    def example(cls) -> ContactLaw:
        """A typical instance (the shared test's and the docs' sample)."""

    @abstractmethod
    def ufl(self, r: ufl.core.expr.Expr) -> ufl.core.expr.Expr:
        """p(r) in UFL (UFL differentiates max_value to the Heaviside: the semismooth Newton's derivative)."""

    @abstractmethod
    def pressure(self, r: np.ndarray) -> np.ndarray:
        """p(r) at points."""

    @abstractmethod
    def slope(self, r: np.ndarray) -> np.ndarray:
        """p'(r) at points (at a kink: the slope on its left)."""

    @abstractmethod
    def inverse(self, pressure: float) -> float:
        """The r >= 0 with p(r) = pressure."""

    @property
    def kinks(self) -> tuple[float, ...]:
        """The r where p' jumps (none here: a law with kinks says where)."""
        return ()

    @property
    def compliance(self) -> float | None:
        """mu with p'(0+) = 1/mu, a fixed scale of the law's stiffness; None where p' has none (power)."""
        return None

    @property
    def stiffness(self) -> float | None:
        """1/mu (:attr:`compliance`), or None."""
        return None if self.compliance is None else 1.0 / self.compliance


@dataclass(frozen=True)
class PiecewiseLinearLaw(ContactLaw):
    """p(r) = sum_j s_j (r - k_j)_+ with kinks k_0 = 0 < k_1 < ... and slope jumps s_j > 0 (:attr:`ramps`)."""

    piecewise_linear: ClassVar[bool] = True

    @property
    @abstractmethod
    def ramps(self) -> tuple[tuple[float, float], ...]:
        """(k_j, s_j) per kink, k_0 = 0 first."""

    @property
    def kinks(self) -> tuple[float, ...]:
        return tuple(k for k, _ in self.ramps)

    def slope(self, r: np.ndarray) -> np.ndarray:
        return self.piece_slope(self.state(r))

    def state(self, r: np.ndarray) -> np.ndarray:
        """The piece r is on: the number of kinks below it (0: no contact)."""
        s = (r > 0.0).astype(np.int8)
        for k, _ in self.ramps[1:]:
            s += (r > k).astype(np.int8)
        return s

    def piece_slope(self, state: np.ndarray) -> np.ndarray:
        """p' on each point's piece."""
        out = np.where(state > 0, self.ramps[0][1], 0.0)
        for j, (_, s) in enumerate(self.ramps[1:], start=1):
            out = np.where(state > j, out + s, out)
        return out

    def piece_pressure(self, r: np.ndarray, state: np.ndarray) -> np.ndarray:
        """p taken affine on each point's piece, at r (p itself where the state is r's)."""
        p = np.where(state > 0, r * self.ramps[0][1], 0.0)
        for j, (k, s) in enumerate(self.ramps[1:], start=1):
            p = p + np.where(state > j, (r - k) * s, 0.0)
        return p

    def crossings(self, r: np.ndarray, s: np.ndarray) -> np.ndarray:
        """Per kink k_j and point, the lam where r + lam s reaches k_j (inf or nan where s = 0)."""
        with np.errstate(divide="ignore", invalid="ignore"):
            return np.concatenate([-r / s, *((k - r) / s for k, _ in self.ramps[1:])])

    def resolvent(self, y: np.ndarray, lam: np.ndarray, omega: np.ndarray) -> np.ndarray:
        """The r with y = (1 - lam omega) r + lam p(r), lam omega < 1 (Bermudez-Moreno's multiplier step).

        On the piece after kink k_j the map is affine with slope a_j = 1 - lam omega + lam (s_0 + ... + s_j)
        and value y_j at k_j (y_0 = 0, y_j = y_{j-1} + a_{j-1} (k_j - k_{j-1})): r = k_j + (y - y_j) / a_j.
        """
        a = 1 - lam * omega + lam * self.ramps[0][1]
        r = np.where(y >= 0, y / a, y / (1 - lam * omega))
        k_prev, y_k = 0.0, 0.0
        for k, s in self.ramps[1:]:
            y_k = y_k + a * (k - k_prev)
            a_next = a + lam * s
            r = np.where(y > y_k, k + (y - y_k) / a_next, r)
            k_prev, a = k, a_next
        return r


@dataclass(frozen=True)
class LinearLaw(PiecewiseLinearLaw):
    """p(r) = r_+ / mu (the paper's)."""

    name: ClassVar[str] = "linear"
    mu: float = 1e-10

    @classmethod
    def parse(cls, table: LawTable) -> LinearLaw:
        mu = table.number("mu", 1e-10)
        _need(table, "mu", mu, mu > 0, "must be > 0 (deformability of the foundation)")
        return cls(mu)

    @classmethod
    def example(cls) -> LinearLaw:
        return cls(1e-3)

    @property
    def ramps(self) -> tuple[tuple[float, float], ...]:
        return ((0.0, 1.0 / self.mu),)

    @property
    def compliance(self) -> float | None:
        return self.mu

    def ufl(self, r: ufl.core.expr.Expr) -> ufl.core.expr.Expr:
        return ufl.max_value(r, 0.0) / constant(r, self.mu)

    def pressure(self, r: np.ndarray) -> np.ndarray:
        return np.maximum(r, 0.0) * (1.0 / self.mu)

    def inverse(self, pressure: float) -> float:
        return self.mu * pressure


@dataclass(frozen=True)
class PowerLaw(ContactLaw):
    """p(r) = c r_+^m, m >= 1 (c = ``coefficient``, m = ``exponent``)."""

    name: ClassVar[str] = "power"
    coefficient: float
    exponent: float

    @classmethod
    def parse(cls, table: LawTable) -> PowerLaw:
        for key in ("coefficient", "exponent"):
            if not table.given(key):
                raise table.fail(key, "<missing>", "law 'power' needs coefficient c and exponent m: p(r) = c r_+^m")
        c = table.number("coefficient")
        _need(table, "coefficient", c, c > 0, "must be > 0")
        m = table.number("exponent")
        _need(table, "exponent", m, m >= 1, "must be >= 1 (p monotone and C^1 for m > 1)")
        return cls(c, m)

    @classmethod
    def example(cls) -> PowerLaw:
        return cls(5.0e4, 1.5)

    @property
    def kinks(self) -> tuple[float, ...]:
        return (0.0,) if self.exponent == 1.0 else ()  # p'(0+) = c for m = 1, 0 for m > 1

    def ufl(self, r: ufl.core.expr.Expr) -> ufl.core.expr.Expr:
        return constant(r, self.coefficient) * ufl.max_value(r, 0.0) ** self.exponent

    def pressure(self, r: np.ndarray) -> np.ndarray:
        # the exponent as an array: numpy's array ** array loop for every m (a scalar m = 2 would take x * x)
        return self.coefficient * np.maximum(r, 0.0) ** np.full(np.shape(r), self.exponent)

    def slope(self, r: np.ndarray) -> np.ndarray:
        return np.where(r > 0.0, self.coefficient * self.exponent * np.maximum(r, 0.0) ** (self.exponent - 1.0), 0.0)

    def inverse(self, pressure: float) -> float:
        return (pressure / self.coefficient) ** (1.0 / self.exponent)


@dataclass(frozen=True)
class LimitedPenetrationLaw(PiecewiseLinearLaw):
    """p(r) = r_+ / mu + (r - d)_+ / mu_stiff: a soft layer of thickness d = ``depth`` on a stiff foundation
    (Signorini's condition at r = d as mu_stiff -> 0)."""

    name: ClassVar[str] = "limited_penetration"
    mu: float
    depth: float
    mu_stiff: float = 1e-10

    @classmethod
    def parse(cls, table: LawTable) -> LimitedPenetrationLaw:
        if not table.given("mu"):
            raise table.fail("mu", "<missing>", "law 'limited_penetration' needs mu (the layer), depth")
        mu = table.number("mu")
        _need(table, "mu", mu, mu > 0, "must be > 0 (deformability of the foundation)")
        if not table.given("depth"):
            raise table.fail("depth", "<missing>", "law 'limited_penetration' needs depth (the layer's thickness)")
        depth = table.number("depth")
        _need(table, "depth", depth, depth > 0, "must be > 0")
        mu_stiff = table.number("mu_stiff", 1e-10)
        _need(table, "mu_stiff", mu_stiff, 0 < mu_stiff <= mu,
              f"must be in (0, mu = {mu}]: the foundation under the layer is the stiffer one")
        return cls(mu, depth, mu_stiff)

    @classmethod
    def example(cls) -> LimitedPenetrationLaw:
        return cls(1e-3, 0.1, 1e-5)

    @property
    def ramps(self) -> tuple[tuple[float, float], ...]:
        return ((0.0, 1.0 / self.mu), (self.depth, 1.0 / self.mu_stiff))

    @property
    def compliance(self) -> float | None:
        return self.mu

    def ufl(self, r: ufl.core.expr.Expr) -> ufl.core.expr.Expr:
        return (ufl.max_value(r, 0.0) / constant(r, self.mu)
                + ufl.max_value(r - constant(r, self.depth), 0.0) / constant(r, self.mu_stiff))

    def pressure(self, r: np.ndarray) -> np.ndarray:
        return np.maximum(r, 0.0) * (1.0 / self.mu) + np.maximum(r - self.depth, 0.0) * (1.0 / self.mu_stiff)

    def inverse(self, pressure: float) -> float:
        r = self.mu * pressure
        if r > self.depth:  # beyond the layer: p = r/mu + (r - d)/mu_stiff
            r = (pressure + self.depth / self.mu_stiff) / (1.0 / self.mu + 1.0 / self.mu_stiff)
        return r


# a scene's law name -> its class, one line a law
CONTACT_LAWS: dict[str, type[ContactLaw]] = {law.name: law for law in (
    LinearLaw,
    PowerLaw,
    LimitedPenetrationLaw,
)}


@dataclass(frozen=True)
class PointLaws:
    """The law at each of many points (the contact term's quadrature points): consecutive runs of points, a
    contact part's on one rank, share one law. Each method evaluates every run with its law's vectorised form."""

    runs: tuple[tuple[ContactLaw, int], ...] = ()  # (law, number of points), in the points' order

    @classmethod
    def join(cls, parts: Iterable[PointLaws]) -> PointLaws:
        """The points of ``parts`` one after another (e.g. every rank's, gathered rank by rank)."""
        return cls(tuple(run for part in parts for run in part.runs))

    @property
    def size(self) -> int:
        return sum(n for _, n in self.runs)

    @property
    def piecewise_linear(self) -> bool:
        """Whether every point's law is piecewise linear."""
        return all(law.piecewise_linear for law, _ in self.runs)

    def _slices(self) -> Iterator[tuple[slice, ContactLaw]]:
        start = 0
        for law, n in self.runs:
            yield slice(start, start + n), law
            start += n

    def _linear(self) -> Iterator[tuple[slice, PiecewiseLinearLaw]]:
        for sl, law in self._slices():
            if not isinstance(law, PiecewiseLinearLaw):
                raise TypeError(f"law {law.name!r} is not piecewise linear")
            yield sl, law

    def column(self, value: Callable[[ContactLaw], float | None]) -> np.ndarray:
        """value(law) at each point (0 where it is None), e.g. ``lambda law: law.stiffness``."""
        out = np.zeros(self.size)
        for sl, law in self._slices():
            v = value(law)
            out[sl] = 0.0 if v is None else v
        return out

    def pressure(self, r: np.ndarray) -> np.ndarray:
        """p(r) per point."""
        p = np.empty_like(r, dtype=float)
        for sl, law in self._slices():
            p[sl] = law.pressure(r[sl])
        return p

    def slope(self, r: np.ndarray) -> np.ndarray:
        """p'(r) per point."""
        out = np.empty_like(r, dtype=float)
        for sl, law in self._slices():
            out[sl] = law.slope(r[sl])
        return out

    def state(self, r: np.ndarray) -> np.ndarray:
        """The piece each point's r is on (piecewise linear laws): the active set."""
        out = np.empty(np.shape(r), dtype=np.int8)
        for sl, law in self._linear():
            out[sl] = law.state(r[sl])
        return out

    def piece_slope(self, state: np.ndarray) -> np.ndarray:
        """p' on each point's piece."""
        out = np.empty(np.shape(state))
        for sl, law in self._linear():
            out[sl] = law.piece_slope(state[sl])
        return out

    def piece_pressure(self, r: np.ndarray, state: np.ndarray) -> np.ndarray:
        """p taken affine on each point's piece, at r."""
        out = np.empty_like(r, dtype=float)
        for sl, law in self._linear():
            out[sl] = law.piece_pressure(r[sl], state[sl])
        return out

    def crossings(self, r: np.ndarray, s: np.ndarray) -> np.ndarray:
        """The lam where some r + lam s reaches a kink of its point's law (unsorted; inf or nan where s = 0)."""
        parts = [law.crossings(r[sl], s[sl]) for sl, law in self._linear()]
        return np.concatenate(parts) if parts else np.zeros(0)

    def resolvent(self, y: np.ndarray, lam: np.ndarray, omega: np.ndarray) -> np.ndarray:
        """Per point, the r with y = (1 - lam omega) r + lam p(r) (:meth:`PiecewiseLinearLaw.resolvent`)."""
        out = np.empty_like(y, dtype=float)
        for sl, law in self._linear():
            out[sl] = law.resolvent(y[sl], lam[sl], omega[sl])
        return out
