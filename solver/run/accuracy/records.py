"""What a plan chose and the estimates behind it, as records (plan.json is :meth:`Plan.summary`)."""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
from mpi4py import MPI

from solver.config import Config
from solver.mesh.geometry import Geometry

from .scene import degrees, merged


@dataclass(frozen=True)
class ErrorEstimate:
    """Bounds of the three parts of the error in the paper's norm (docs/model.md §3.6)."""

    space_u: float  # C times the estimator's indicator, times its growth over the run
    space_zeta: float  # the damage's space error, from nested meshes
    time: float  # the time error of the chosen step, by step doubling (adaptive steps: the controller's tolerance)
    model: float = 0.0  # the changes of the ingredients accuracy.simplify left out (ingredients.py)

    @property
    def total(self) -> float:
        return self.space_u + self.space_zeta + self.time + self.model

    def as_dict(self) -> dict[str, float]:
        out = {"space_u": self.space_u, "space_zeta": self.space_zeta, "time": self.time}
        if self.model:
            out["model"] = self.model
        return out


@dataclass(frozen=True)
class MeshRecord:
    """One mesh the planner solved on: its size, the estimator's indicator and the bound C times it."""

    degree: int
    cells: int
    dofs: int
    indicator: float  # the residual estimator's eta (docs: solver/physics/estimator.py)
    estimate: float  # C times ``indicator``
    uniform: bool = False  # a uniform refinement (for the damage's part), not a Dörfler step
    geo: Geometry | None = None  # the mesh of a Dörfler step (zeta's nested chain is drawn from them)
    seconds: float = 0.0  # the round's wall time: the refinement that made the mesh, its solve and estimate

    def summary(self) -> dict:
        """The record as plan.json writes it (``seconds`` where measured)."""
        out = {"degree": self.degree, "cells": self.cells, "dofs": self.dofs, "eta": self.indicator,
               "estimate": self.estimate}
        if self.uniform:
            out["uniform"] = True
        if self.seconds:
            out["seconds"] = self.seconds
        return out


@dataclass(frozen=True)
class Plan:
    """What the tolerance chose, and the estimates behind it."""

    tolerance: float  # absolute
    degree: int
    order: int
    k: float
    geo: Geometry  # the chosen (adapted) mesh
    start: dict  # the start mesh's changes to the scene ({} or {"mesh": {"nx": .., "ny": ..}})
    estimate: ErrorEstimate
    C: float  # the estimator's constant for the chosen degree and material
    growth: float  # the indicator's growth over the run on the start mesh
    time_rate: float  # the observed order in the step
    time_profile: tuple[np.ndarray, np.ndarray]  # (t, estimated time error at k) from the pilot runs
    adaptation: tuple[MeshRecord, ...]
    seconds: float  # planning time
    scene: Config  # the scene planned for
    stages: dict = field(default_factory=dict)  # seconds per stage of the planning
    calibration: object = None  # the estimator constant's calibration on the scene (calibration.Calibration), or None
    ingredients: tuple = ()  # each optional ingredient's change of the answer (ingredients.Ingredient)
    # the displacement of the last t = 0 solve on ``geo`` at ``degree`` (this process's array, ghosts included), the
    # run's level-0 Newton start (:meth:`warm_start`); None where the mesh was fitted to a later level
    level0_u: np.ndarray | None = field(default=None, repr=False, compare=False)
    # the run's step controller chooses the steps (accuracy.time = "adaptive"): ``k`` is its first step and
    # ``estimate.time`` its time.tolerance
    adaptive: bool = False

    def warm_start(self, model) -> bool:
        """Start ``model``'s level-0 Newton (the run's, built on ``geo`` at ``degree``: the same space, so the same
        dof layout) from the planner's last t = 0 solution, which solved that very problem; False (nothing set)
        where there is none or the sizes differ on any process. Collective."""
        ok = self.level0_u is not None and model.u.x.array.size == self.level0_u.size and model.geo is self.geo
        if not model.geo.comm.allreduce(ok, op=MPI.LAND):
            return False
        model.u.x.array[:] = self.level0_u
        return True

    @property
    def changes(self) -> dict:
        """The changes to the scene of the chosen degrees, order and step (the mesh is ``geo``; adaptive: the first
        step and the controller's tolerance)."""
        timed = {"order": self.order, "k": self.k}
        if self.adaptive:
            timed.update({"adaptive": True, "tolerance": self.estimate.time})
        return merged(self.start, degrees(self.degree), {"time": timed})

    @property
    def config(self) -> Config:
        """The scene planned for with the chosen degrees, order and step: what the run is built from."""
        return self.scene.replace(self.changes, label="plan")

    def time_error(self, t: float) -> float:
        """The estimated time error at time ``t`` (the profile's last level at or before it)."""
        ts, es = self.time_profile
        i = int(np.searchsorted(ts, t + 1e-12 * max(1.0, t), side="right")) - 1
        return float(es[max(i, 0)]) if len(es) else 0.0

    def summary(self) -> dict:
        """plan.json's content."""
        return {"tolerance": self.tolerance, "u_degree": self.degree, "zeta_degree": self.degree, "order": self.order,
                "k": self.k, "time": "adaptive" if self.adaptive else "uniform", "cells": self.geo.num_cells(),
                "estimate": self.estimate.as_dict(), "C": self.C,
                "growth": self.growth, "time_rate": self.time_rate,
                "adaptation": [r.summary() for r in self.adaptation], "planning_seconds": self.seconds,
                "planning_stages": self.stages,
                "calibration": None if self.calibration is None else self.calibration.summary(),
                "ingredients": {i.name: i.summary() for i in self.ingredients},
                "left_out": [i.name for i in self.ingredients if i.dropped]}
