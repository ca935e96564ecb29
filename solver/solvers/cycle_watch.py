"""Cycle detection for semismooth Newton with a piecewise-linear contact law (docs/model.md §4).

With such a law (and no implicit memory term) the residual is affine on each active set, so a Newton iterate
depends only on the active set of the iterate before it: an active set met again, other than the last one,
means Newton cycles and would go on until max_it.
"""

from __future__ import annotations

from mpi4py import MPI
from petsc4py import PETSc

# SNES has no reason code for a cycle: this one stands for it inside the solver (named CYCLE to the user)
DIVERGED_CYCLE = PETSc.SNES.ConvergedReason.DIVERGED_INNER
CYCLE = "DIVERGED_ACTIVE_SET_CYCLE"
# ... nor for a Newton step whose end keeps the active set it was solved on (the piecewise linear law's finite
# termination: the step solved that set's linear equations, so its end is the level's solution to round-off)
CONVERGED_SET = PETSc.SNES.ConvergedReason.CONVERGED_ITS


class ActiveSetCycleWatch:
    """Remembers the active-set fingerprints of one level's iterates and says when one is revisited.

    ``enabled``: the problem is one where a revisit means a cycle (see the module docstring). Between
    :meth:`start` and :meth:`stop` (plain Newton only: the damped fallback may revisit an active set) the
    watch is ``watching``; ``cycled`` tells whether that level's watch saw a cycle.
    """

    def __init__(self, comm: MPI.Comm, enabled: bool) -> None:
        self.comm, self.enabled = comm, enabled
        self.watching = False
        self.cycled = False
        self._seen: list[bytes] = []  # the fingerprints of this level's iterates, in order

    def start(self) -> None:
        """A new level: forget the earlier levels' active sets."""
        self._seen.clear()
        self.watching, self.cycled = self.enabled, False

    def stop(self) -> None:
        self.watching = False

    @property
    def started(self) -> bool:
        """Whether the level's first iterate is recorded."""
        return bool(self._seen)

    def first(self, key: bytes) -> None:
        """Record the level's first iterate's active set."""
        self._seen.append(key)

    def revisited(self, key: bytes) -> bool:
        """Record an iterate's active set; True if it is one of the earlier iterates' but the last (collective:
        a set is met again when it is on every rank). A True sets ``cycled``."""
        again = key in self._seen[:-1]
        self._seen.append(key)
        again = self.comm.allreduce(again, op=MPI.LAND)
        self.cycled = self.cycled or again
        return again
