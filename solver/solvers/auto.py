"""``solver.method = "auto"`` (the default): plain Newton while it solves the levels, newton_condensed from the
first level it does not (docs/model.md §4).

Where the contact zone stays put, a Newton level is one solve with a reused factorization; there newton_condensed
pays two or three solves with K per level. Where the zone moves by many points per level, plain semismooth Newton
cycles between active sets and its damped fallback takes tens of iterations, each a factorization of K + C, while
newton_condensed solves those levels on the contact dofs with K's one factorization (measured: docs/model.md §4).
So a run starts with Newton, without its fallback and with at most NEWTON_ITERATIONS iterations a level, and at
the first level Newton does not solve (a cycle of active sets, no convergence, a failed linear solve, or GROWTH_STEPS
iterations in a row each raising ||F||: a Newton that has started to diverge) that level is solved again from its
start by the take-over method, and so is every later one. The switch depends on the iterates
only, never on timings: the same scene takes the same path on every machine.

The take-over is newton_condensed where it applies, else newton_energy (the registry's fallback, methods.py); both
share Newton's SNES and KSP (:class:`~newton.NewtonCore`). Where there is no energy to work on (the implicit memory
rule), or with ``solver.newton_fallback = false``, there is no take-over: the method is Newton with its own
fallback setting (a failed level fails where it is off).

A first contact (no point in contact at the level's start) after the run's first level that Newton's first
FIRST_STEPS iterations do not solve is handed over there, without Newton's compliance path in the full space, where
the take-over has a path of its own (newton_condensed in 2-D: the path on the contact dofs, no factorization a
stage): where Newton's path does not settle the level its stages are lost with it. At the run's first level Newton
keeps its path: there the hand-over also pays S's build for a run that may stay on Newton (measurements in
docs/model.md §4).
"""

from __future__ import annotations

import logging
from dataclasses import replace

from solver.errors import DisplacementSolveError
from solver.physics.displacement import SolveInfo
from solver.solvers.damped_newton import FALLBACK_IT_FACTOR
from solver.solvers.method import DisplacementMethod
from solver.solvers.newton import NewtonSolver

# Newton's iterations on a level before auto hands it over (of solver.max_it): a level Newton has not solved in 8
# is one whose active set keeps changing (the measurements: docs/model.md §4)
NEWTON_ITERATIONS = 8
# ... and the number of iterations in a row, each raising ||F||, after which it hands the level over at once
GROWTH_STEPS = 2

log = logging.getLogger("solver")


class AutoSolver(DisplacementMethod):
    """``newton``'s levels until one fails, then ``takeover``'s (module docstring). ``newton`` is built with at
    most NEWTON_ITERATIONS iterations a level and no fallback where there is a take-over; ``takeover`` None: Newton
    alone."""

    def __init__(self, newton: NewtonSolver, takeover: DisplacementMethod | None) -> None:
        self.newton, self.takeover = newton, takeover
        self.core = newton.core  # the SNES, KSP and counters both methods share
        self.switched_at: int | None = None  # the level (count of levels solved before it) it switched at
        self.levels = 0
        self._start = newton.problem.u.vector.duplicate() if takeover is not None else None
        if takeover is not None:  # auto's own retry on the direct solver (solve), not each method's
            newton.retry_direct = takeover.retry_direct = False

    @property
    def switched(self) -> bool:
        return self.switched_at is not None

    @property
    def fallbacks(self) -> int:
        return self.newton.fallbacks + (self.takeover.fallbacks if self.takeover is not None else 0)

    def solve(self, scale: float) -> SolveInfo:
        """The level by Newton, or (from the first level Newton fails) by the take-over method."""
        self.levels += 1
        if self.takeover is None:
            return self.newton.solve(scale)
        u, core = self.newton.problem.u, self.newton.core
        # a first contact after the run's first level goes to the take-over's own path (module docstring)
        self.newton.take_path = not (self.takeover.has_path and self.levels > 1)
        core.begin_level()  # back to the iterative solver after the levels the direct one took (NewtonCore)
        u.vector.copy(self._start)
        f0 = core.factorizations
        if self.switched:  # the take-over's level; where its linear solve fails, again from its start, directly
            return core.solve_level(lambda: self._handed_over(scale), self._start)
        core.test.growth_limit = GROWTH_STEPS
        try:
            return self.newton.solve(scale)
        except DisplacementSolveError as exc:
            failed = exc
        finally:
            core.test.growth_limit = None
        # the level again, from its start, or first, on a first contact handed to a method that may start anywhere
        # (newton_energy), from where the compliance path ended: the zone there is the stiff one's to within a ring
        # of points, where from the start newton_energy's damped steps shrink the undamped solve's zone by a ring
        # every few iterations (the sphere at h = 0.03: 17 iterations against 71; docs/model.md §4)
        # A failed linear solve of the iterative solver (CG + GAMG indefinite on the stiff law's J: the sphere at
        # h = 0.015, docs/model.md §4) puts the core on the direct solver for the rest of the run, and a take-over
        # whose linear solve failed is tried again from the same start
        self.switched_at = self.levels - 1
        self._direct_if_linear_failed(failed)
        starts = [self.newton.path_end] if self.newton.path_end is not None and self.takeover.starts_anywhere else []
        spent = failed.iterations
        tries = [*starts, self._start]
        while tries:
            start = tries[0]
            start.copy(u.vector)
            u.x.scatter_forward()
            try:
                info = self._handed_over(scale)
                break
            except DisplacementSolveError as exc:
                spent += exc.iterations
                if self._direct_if_linear_failed(exc):
                    continue  # the same start, solved directly
                tries.pop(0)
                if not tries:
                    raise
        return replace(info, iterations=info.iterations + spent, linear_solves=info.linear_solves + spent,
                       factorizations=core.factorizations - f0)

    def _direct_if_linear_failed(self, exc: DisplacementSolveError) -> bool:
        """Put the core on the direct solver where ``exc`` is a failed iterative linear solve; whether it did."""
        if exc.linear_reason >= 0 or not self.core.iterative:
            return False
        log.info("the iterative linear solver failed: the level is solved again by MUMPS's direct solver")
        self.core.use_direct()
        return True

    def _handed_over(self, scale: float) -> SolveInfo:
        """The take-over's solve of a level, with the damped fallback's budget (FALLBACK_IT_FACTOR times its limit),
        the level handed over and every later one: a first contact in 3-D takes some 40 of its iterations, and so
        does the next level of a sphere pressed further (docs/model.md §4)."""
        test = self.takeover.test
        limit = test.max_it
        test.max_it = FALLBACK_IT_FACTOR * limit
        try:
            return self.takeover.solve(scale)
        finally:
            test.max_it = limit

    def state(self):
        """The take-over's carried arrays (newton_condensed's predictor)."""
        return self.takeover.state() if self.takeover is not None else {}

    def restore(self, name, values) -> None:
        if self.takeover is None:
            super().restore(name, values)
        else:
            self.takeover.restore(name, values)

    def scalars(self) -> dict[str, float]:
        """What a checkpoint carries of the switch: the level it was made at (-1: not yet), and whether the
        iterative linear solver was replaced by the direct one (:meth:`NewtonCore.use_direct`)."""
        return {"switched_at": float(-1 if self.switched_at is None else self.switched_at),
                "levels": float(self.levels), **self.core.scalars()}

    def restore_scalars(self, scalars: dict[str, float]) -> None:
        """Take back :meth:`scalars`: a restarted run goes on with the method the checkpointed one had."""
        at = int(scalars.get("switched_at", -1))
        self.levels = int(scalars.get("levels", 0))
        if at >= 0:
            self.switched_at = at
        self.core.restore_scalars(scalars)
