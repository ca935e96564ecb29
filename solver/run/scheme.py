"""The time scheme (docs/model.md §3.6, §3.7): what each of a level's three steps does, per order.

Level n-1 -> n is: 1. memory (M_n from level n-1), 2. damage (zeta_n), 3. displacement (u_n).
What the scheme is (the memory rule, the damage step, the start-up) is decided once, by
:class:`solver.config.time.TimeScheme`, from which the model is built; the classes here carry it out
on the model's parts (:class:`LevelParts`). :class:`FirstOrderScheme` is the paper's: the
left-rectangle or trapezoidal memory sum and the explicit or semi-implicit damage step.
:class:`SecondOrderScheme` adds the trapezoid's current term at an extrapolated u, the CN-AB2 damage
step, and, where the TimeScheme says so, its start-up: at n = 1 a Heun predictor-corrector, since AB2
and the extrapolation need two past levels.
"""

from __future__ import annotations

from typing import Protocol

from dolfinx import fem

from solver.config.time import TimeScheme
from solver.physics.memory import History
from solver.solvers.damage_step import Damage, DamageStepInfo
from solver.solvers.mechanics import Mechanics


class LevelParts(Protocol):
    """What a scheme steps: the fields and solvers of a model (:class:`solver.run.model.Model` is one)."""

    @property
    def u(self) -> fem.Function: ...

    @property
    def u_prev(self) -> fem.Function | None: ...

    @property
    def damage(self) -> Damage | None: ...

    @property
    def history(self) -> History | None: ...

    @property
    def mech(self) -> Mechanics: ...


class FirstOrderScheme:
    """Implicit Euler in time with the history and the damage source from level n-1."""

    def __init__(self, model: LevelParts, scheme: TimeScheme) -> None:
        self.model = model
        self.scheme = scheme

    def set_step(self, k: float, k_prev: float | None) -> None:
        """Level n goes over k = t_n - t_{n-1}; ``k_prev`` = t_{n-1} - t_{n-2} (None at n = 1): the history's and
        the damage step's weights (docs/model.md §3.9)."""
        if self.model.history is not None:
            self.model.history.set_step(k, k_prev)
        if self.model.damage is not None:
            self.model.damage.set_step(k, k_prev)

    def memory(self, n: int) -> None:
        """1. M_n from (u_{n-1}, zeta_{n-1}): level n-1 converged, so it is committed now."""
        if self.model.history is not None:
            self.model.history.commit(n - 1)

    def damage(self, n: int) -> DamageStepInfo | None:
        """2. zeta_{n-1} -> zeta_n (uses u_{n-1}, zeta_{n-1}); None without damage."""
        return self.model.damage.step() if self.model.damage is not None else None

    def displacement(self, n: int, t: float, dinfo: DamageStepInfo | None):
        """3. u_n with M_n; returns the solve's info and the level's damage info."""
        return self.model.mech.solve(t), dinfo


class SecondOrderScheme(FirstOrderScheme):
    """Trapezoidal memory with the current term at u* = 2 u_{n-1} - u_{n-2}, CN-AB2 damage; Heun's start."""

    def damage(self, n: int) -> DamageStepInfo | None:
        """2. zeta_n by CN-AB2, then M_n's current term at u* (it needs zeta_n)."""
        dinfo = super().damage(n)
        if self.model.u_prev is not None:
            self._extrapolated_memory(n)
        return dinfo

    def _extrapolated_memory(self, n: int) -> None:
        """M_n = P_n + (k/2) g(0) H(u*, zeta_n), u* = 2 u_{n-1} - u_{n-2} (u_0 at n = 1; variable steps:
        u_{n-1} + (k_n / k_{n-1}) (u_{n-1} - u_{n-2})); then u_prev = u_{n-1}.

        H(u*) comes from the strains of u_{n-1} (just committed) and u_{n-2} by linearity: no third product."""
        model = self.model
        model.history.extrapolate(model.u_prev.x.array if n >= 2 else None)
        model.u_prev.x.array[:] = model.u.x.array

    def displacement(self, n: int, t: float, dinfo: DamageStepInfo | None):
        """3. u_n; at n = 1 u_1 is a predictor, corrected by :meth:`_heun_corrector`."""
        info, dinfo = super().displacement(n, t, dinfo)
        if n == 1 and self.scheme.heun_start:
            return self._heun_corrector(t, info, dinfo)
        return info, dinfo

    def _heun_corrector(self, t: float, info, dinfo: DamageStepInfo | None):
        """Correct zeta_1 and M_1 with the predicted u_1, then solve u_1 again; the level counts both solves."""
        model = self.model
        if model.damage is not None:
            c = model.damage.correct_first_step()
            dinfo = DamageStepInfo(c.clipped, c.raw_min, c.raw_max, dinfo.krylov_iterations + c.krylov_iterations)
        if model.u_prev is not None:
            model.history.extrapolate(None)  # H(u_1, zeta_1), both predicted
        again = model.mech.solve(t)
        again.iterations += info.iterations
        again.linear_solves += info.linear_solves
        again.factorizations += info.factorizations
        again.krylov_iterations += info.krylov_iterations
        return again, dinfo


def level_scheme(model: LevelParts, scheme: TimeScheme) -> FirstOrderScheme:
    """The steps of ``scheme``'s order, on the model's parts."""
    return (SecondOrderScheme if scheme.order == 2 else FirstOrderScheme)(model, scheme)
