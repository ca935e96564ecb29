"""The run's error sensor: at every level, the plan's bound of the space part (C eta_n + zeta's part) and of the
time part, as the CSV columns ``est_space`` and ``est_time``. eta_n is evaluated on about SAMPLES levels spread
over the run and the last (a level between two carries the last evaluated): on Example 1's 80-step plan an
evaluation at every level was a quarter of the run's time, and eta varies smoothly over a run (docs/guide/accuracy.md)."""

from __future__ import annotations

import math
from dataclasses import dataclass

from solver.physics.estimator import estimator_for
from solver.run.model import Model

from .records import Plan

SAMPLES = 10  # levels besides the first and the last at which eta_n is evaluated


@dataclass
class Largest:
    """The largest estimates over the levels seen so far."""

    space: float = 0.0
    time: float = 0.0
    total: float = 0.0


class ErrorSensor:
    """A sensor for :func:`solver.run.stepper.levels`: the run's estimated error per level, from ``plan``."""

    columns = ("est_space", "est_time")

    def __init__(self, model: Model, plan: Plan) -> None:
        self.est = estimator_for(model)
        self.plan = plan
        self.largest = Largest()
        self.steps = model.cfg.time.steps
        self.every = max(1, math.ceil(self.steps / SAMPLES))
        self.eta = 0.0

    def __call__(self, row: dict) -> dict:
        n = row.get("step", 0)
        if n % self.every == 0 or n >= self.steps or row["t"] >= self.plan.scene.time.T * (1 - 1e-12):
            self.eta = self.est.total()
        space = self.plan.C * self.eta + self.plan.estimate.space_zeta
        tim = self.plan.time_error(row["t"])
        self.largest.space = max(self.largest.space, space)
        self.largest.time = max(self.largest.time, tim)
        self.largest.total = max(self.largest.total, space + tim + self.plan.estimate.model)
        return {"est_space": space, "est_time": tim}
