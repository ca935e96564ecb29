"""The interface of a displacement method: one level per :meth:`DisplacementMethod.solve`, and what a checkpoint
carries of the method itself (empty for most: only what a restarted run needs to take the same iterations)."""

from __future__ import annotations

from abc import ABC, abstractmethod

import numpy as np

from solver.physics.displacement import SolveInfo


class DisplacementMethod(ABC):
    """Solves a level's displacement problem (u holds the previous level as initial guess; DisplacementSolveError
    where it fails). The checkpoint hooks default to nothing carried."""

    # whether a level may be started from any iterate (auto's take-over of a first contact starts it where the
    # compliance path ended); False where the method predicts from the level's start (newton_condensed)
    starts_anywhere = False
    # whether a level that starts with no point in contact gets the method's own compliance path (auto then hands
    # such a level over after Newton's first steps instead of taking Newton's path in the full space)
    has_path = False

    @abstractmethod
    def solve(self, scale: float) -> SolveInfo:
        """Solve the level whose force scale is ``scale``."""

    @property
    def fallbacks(self) -> int:
        """Levels solved by a damped fallback (none for most methods)."""
        return 0

    def state(self) -> dict[str, np.ndarray]:
        """Arrays the method carries from level to level (owned dof values, by name)."""
        return {}

    def restore(self, name: str, values: np.ndarray) -> None:
        """Take back :meth:`state`'s ``name`` from a checkpoint."""
        raise KeyError(f"{type(self).__name__} carries no array {name!r}")

    def scalars(self) -> dict[str, float]:
        """Numbers the method carries from level to level."""
        return {}

    def restore_scalars(self, scalars: dict[str, float]) -> None:
        """Take back :meth:`scalars` (given with the other carried numbers: a method reads only its own)."""
        return None
