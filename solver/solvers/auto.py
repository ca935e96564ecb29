"""``solver.method = "auto"`` (the default): plain Newton while it solves the levels, ``newton_condensed`` from the
first level it does not (docs/model.md §4).

Where the contact zone stays put, a Newton level is one solve with a reused factorization, the floor; there
newton_condensed pays two or three solves with K per level (1.2-1.8 times Newton's time on Example 1,
benchmarks/results/work_precision.csv). Where the zone moves by many points per level, plain semismooth Newton
cycles between active sets and its damped fallback takes tens of iterations, each a factorization of K + C;
newton_condensed solves those levels on the contact dofs with K's one factorization (0.07 of the time on hard.toml
with P2 at n = 48). So a run starts with Newton, without its fallback, and at the first level Newton does not solve
in NEWTON_ITERATIONS (a cycle of active sets, no convergence in 8 iterations, a failed linear solve) that level is
solved again from its start by newton_condensed, and so is every later one. The switch depends on the iterates
only, never on timings: the same scene takes the same path on every machine. Where newton_condensed has no energy
to work on (the implicit memory rule) there is nothing to switch to, and the method is Newton with its fallback;
with ``solver.newton_fallback = false`` a failed level fails, as Newton's does.
"""

from __future__ import annotations

from dataclasses import replace

import numpy as np
from mpi4py import MPI

from solver.config import SolverConfig
from solver.errors import DisplacementSolveError
from solver.physics.contact_points import ContactPoints
from solver.physics.displacement import DisplacementProblem, SolveInfo
from solver.solvers.condensed import CondensedNewtonSolver
from solver.solvers.newton import NewtonSolver

# Newton's iterations on a level before auto hands it over (of solver.max_it): a level Newton has not solved in 8
# is one whose active set keeps changing. hard.toml, P2, order 2, n = 48, k = 0.0125 (python scripts/nonlinear_bench.py
# cases, one run each): 224 iterations, at most 25 on a level, with max_it (25) as the limit; 206 / 19 at 12, 202 / 15
# at 8, 200 / 13 at 6; P1 levels of hard.toml take at most 5 (n = 16 ... 64), Example 1's 1.
NEWTON_ITERATIONS = 8


class AutoSolver(CondensedNewtonSolver):
    """Newton's levels until one fails, then :class:`CondensedNewtonSolver`'s (module docstring)."""

    def __init__(self, problem: DisplacementProblem, settings: SolverConfig, comm: MPI.Comm, facets: np.ndarray,
                 fdim: int, points: ContactPoints | None = None) -> None:
        super().__init__(problem, settings, comm, facets, fdim, points)
        # newton_condensed (or newton_energy) can take a level over; solver.newton_fallback = false: none may
        self.switchable = self.energy and settings.newton_fallback
        self.switched_at: int | None = None  # the level (count of levels solved before it) it switched at
        self.levels = 0
        if self.switchable:
            self.fallback.allowed = False  # a failed Newton level goes to newton_condensed instead
            self.test.max_it = min(settings.max_it, NEWTON_ITERATIONS)
            self._start = problem.u.vector.duplicate()

    @property
    def switched(self) -> bool:
        return self.switched_at is not None

    def solve(self, scale: float) -> SolveInfo:
        """The level by Newton, or (from the first level Newton fails) by newton_condensed."""
        self.levels += 1
        if self.switched:
            return super().solve(scale)
        if not self.switchable:
            return NewtonSolver.solve(self, scale)
        u = self.problem.u
        u.vector.copy(self._start)
        f0 = self.factorizations
        try:
            return NewtonSolver.solve(self, scale)
        except DisplacementSolveError as exc:
            failed = exc
        self._start.copy(u.vector)  # the level again, from its start
        u.x.scatter_forward()
        self._switch(self.levels - 1)
        info = super().solve(scale)
        return replace(info, iterations=info.iterations + failed.iterations,
                       linear_solves=info.linear_solves + failed.iterations,
                       factorizations=self.factorizations - f0)

    def _switch(self, level: int) -> None:
        """From ``level`` on, newton_condensed's levels, with the scene's iteration limit."""
        self.switched_at = level
        self.test.max_it = self.settings.max_it

    def scalars(self) -> dict[str, float]:
        """What a checkpoint carries of the switch: the level it was made at (-1: not yet)."""
        return {"switched_at": float(-1 if self.switched_at is None else self.switched_at),
                "levels": float(self.levels)}

    def restore_scalars(self, scalars: dict[str, float]) -> None:
        """Take back :meth:`scalars`: a restarted run goes on with the method the checkpointed one had."""
        at = int(scalars.get("switched_at", -1))
        self.levels = int(scalars.get("levels", 0))
        if at >= 0:
            self._switch(at)
