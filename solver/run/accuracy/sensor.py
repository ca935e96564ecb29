"""The run's error sensor: at every level, the plan's bound of the space part (C eta_n + zeta's part) and of the
time part, as the CSV columns ``est_space`` and ``est_time``."""

from __future__ import annotations

from dataclasses import dataclass

from solver.physics.estimator import estimator_for
from solver.run.model import Model

from .records import Plan


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

    def __call__(self, row: dict) -> dict:
        space = self.plan.C * self.est.total() + self.plan.estimate.space_zeta
        tim = self.plan.time_error(row["t"])
        self.largest.space = max(self.largest.space, space)
        self.largest.time = max(self.largest.time, tim)
        self.largest.total = max(self.largest.total, space + tim)
        return {"est_space": space, "est_time": tim}
