"""The time loop of Problem VP^hk (docs/model.md §3.6).

:meth:`Stepper.step` advances level n-1 -> n, with only data of level n-1 on the right-hand sides
(what each step does per order: :mod:`solver.run.scheme`, the order's choices being the model's
:class:`solver.config.time.TimeScheme`):
  1. memory: M_n from (u_{n-1}, zeta_{n-1}) -- level n-1 converged, so it is committed now;
  2. damage: zeta_{n-1} -> zeta_n (uses u_{n-1}, zeta_{n-1});
  3. displacement: u_n with M_n;
and returns the level's row (solver figures, diagnostics, timings). Level 0 is the elastic
contact problem with M_0 = 0 and zeta_0 = zeta0. :func:`levels` is the loop around it,
a generator of rows that writes nothing: :func:`solver.io.results.run` writes what it yields
(fields, the CSV row, checkpoints) and restarts.
"""

from __future__ import annotations

import time
from collections.abc import Iterator

from mpi4py import MPI

from solver.errors import NonFiniteError, SolveFailure
from solver.physics.diagnostics import DamageDiagnostics
from solver.physics.quadrature import all_finite
from solver.run.adaptive import StepController
from solver.run.model import Model
from solver.run.scheme import level_scheme

TIMING_COLUMNS = ("time_damage", "time_memory", "time_displacement", "time_diagnostics", "time_output", "wall_time")


class Stepper:
    """Advances a model one time level at a time; each :meth:`step` returns the level's row."""

    def __init__(self, model: Model, diagnostics: bool = True) -> None:
        """``diagnostics`` False: a row without the contact's, the strain's and zeta's norms (for runs that read only
        the fields, as the tolerance planner's pilots do: the first row builds the contact traces and the strain
        norm's Gram matrix)."""
        self.model, self.diagnostics = model, diagnostics
        self.k = model.cfg.time.k
        self.damage_diagnostics = DamageDiagnostics(model.geo.mesh, model.damage, model.cfg.damage.zeta0)
        self.scheme = level_scheme(model, model.scheme)

    def step(self, n: int, t: float | None = None, k: float | None = None, k_prev: float | None = None) -> dict:
        """Level n (n = 0: the initial elastic contact problem). Raises a SolveFailure that knows n and t.

        ``t``, ``k``, ``k_prev``: variable steps, level n at t = t_{n-1} + k after a step k_prev (None at n = 1);
        by default the uniform steps of the scene, t = n k."""
        scheme = self.scheme
        if t is None:
            t, k, k_prev = n * self.k, self.k, (self.k if n >= 2 else None)
        t0 = time.perf_counter()
        dinfo = None
        try:
            if n > 0:
                scheme.set_step(k, k_prev)
                scheme.memory(n)  # 1. M_n from level n-1
            t1 = time.perf_counter()
            if n > 0:
                dinfo = scheme.damage(n)  # 2. zeta_n
            t2 = time.perf_counter()
            info, dinfo = scheme.displacement(n, t, dinfo)  # 3. u_n
            self._check_finite()
        except SolveFailure as exc:
            raise exc.at(n, t) from None
        t3 = time.perf_counter()
        zmin, zmax = self.damage_diagnostics.zeta_range()
        # the range before clipping (level 0 or no damage: the field's)
        raw = (dinfo.raw_min, dinfo.raw_max) if dinfo is not None else (zmin, zmax)
        clipped, dkrylov = (dinfo.clipped, dinfo.krylov_iterations) if dinfo is not None else (0, 0)
        row = {
            "step": n, "t": t, "newton_iterations": info.iterations, "linear_solves": info.linear_solves,
            "factorizations": info.factorizations, "residual": info.residual,
            "krylov_iterations": info.krylov_iterations, "damage_krylov_iterations": dkrylov,
            **(self.model.mech.diagnostics.row() if self.diagnostics else {}),
            "zeta_min": zmin, "zeta_max": zmax, "zeta_raw_min": raw[0], "zeta_raw_max": raw[1], "zeta_clipped": clipped,
        }
        if self.diagnostics:
            row["zeta_norm"] = self.damage_diagnostics.zeta_norm()
        t4 = time.perf_counter()
        row.update({"time_memory": t1 - t0, "time_damage": t2 - t1, "time_displacement": t3 - t2,
                    "time_diagnostics": t4 - t3})
        return row

    def _check_finite(self) -> None:
        model = self.model
        bad = []
        if not all_finite(model.u.x.array):
            bad.append("displacement")
        if model.damage is not None and not all_finite(model.damage.zeta.x.array):
            bad.append("damage")
        if model.history is not None and not model.history.finite():
            bad.append("memory")
        bad = model.comm.allreduce(bad, op=MPI.SUM)
        if bad:
            raise NonFiniteError(bad)


def writes_level(n: int, steps: int, every: int) -> bool:
    """Whether level n is written: every N-th level and the last; every=0: first and last."""
    if n == 0 or n == steps:
        return True
    return every > 0 and n % every == 0


def written_levels(first: int, last: int, steps: int, every: int) -> int:
    """How many of the levels first..last (both included) :func:`writes_level` writes, counted without a loop."""
    if last < first:
        return 0
    if every <= 0:  # the first and last levels only
        return sum(1 for m in {0, steps} if first <= m <= last)
    # the multiples of every (level 0 among them), and the last level where it is not one
    return last // every - (first - 1) // every + (1 if first <= steps <= last and steps % every else 0)


def levels(model: Model, start: int = 0, sensors: tuple = (), times=None, clock=None,
           diagnostics: bool = True) -> Iterator[dict]:
    """Solve levels ``start``..steps of the model's scene, yielding each level's row; writes nothing.

    ``sensors``: objects with ``columns`` and ``sensor(row) -> dict`` that add their columns to
    every level's row (e.g. the error estimates of a tolerance run); their time counts as
    diagnostics. A row's ``time_output`` is 0 here and ``wall_time`` the sum of its parts; a
    writer adds the time it takes to both.

    ``times``: variable steps given in advance, the levels' times t_0 = 0 < t_1 < ... (``start`` 0 only).
    ``clock``: an adaptive run's :class:`solver.run.adaptive.StepController`, which chooses the steps (and
    carries the step history a checkpoint keeps); by default the scene's (uniform, or adaptive with a new
    controller). ``diagnostics`` False: rows without the diagnostics' columns (:class:`Stepper`), except with a
    step controller (it reads the contact length).
    """
    if clock is None and model.cfg.time.adaptive:
        clock = StepController(model)
    stepper = Stepper(model, diagnostics or clock is not None)
    if clock is not None:
        rows = clock.levels(stepper, start)
    elif times is not None:
        if start != 0:
            raise ValueError("levels with given times start at level 0")
        rows = (stepper.step(n, times[n], times[n] - times[n - 1] if n else 0.0,
                             times[n - 1] - times[n - 2] if n >= 2 else None) for n in range(len(times)))
    else:
        rows = (stepper.step(n) for n in range(start, model.cfg.time.steps + 1))
    for row in rows:
        if sensors:
            t0 = time.perf_counter()
            for sensor in sensors:
                row.update(sensor(row))
            row["time_diagnostics"] += time.perf_counter() - t0
        row["time_output"] = 0.0
        row["wall_time"] = sum(row[c] for c in TIMING_COLUMNS[:-1])
        yield row
