"""The time part (docs/guide/accuracy.md, "step").

``accuracy.time = "uniform"`` (:func:`choose_step`): step doubling on the start mesh. Runs at k0, k0/2 and k0/4
(k0 = T/N0) give the observed order p (at most the scheme's) and the error of k0/4, D/(2^p - 1), in the paper's
norm (docs/model.md §3.6); the step is the largest T/n (n >= N0) whose extrapolated error is within SAFETY times
the time's share of the tolerance.

``accuracy.time = "adaptive"`` (:func:`controller_step`): the run's step controller (``time.adaptive``,
docs/model.md §3.9) keeps the time error within ``time.tolerance``, the time's share of the tolerance; one pilot
run at k0 (the indicator's growth, the ingredients' changes) and no step doubling.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass, replace

import numpy as np
import ufl
from dolfinx import fem
from mpi4py import MPI

from solver.config import Config
from solver.errors import SolveFailure, ToleranceError
from solver.mesh.geometry import Geometry
from solver.run.model import Model

from .scene import step, with_changes
from .solves import PilotRun, pilot_run

N0 = 10  # the coarsest step is T / N0; every step considered is T / n, n >= N0
SAFETY = 0.8  # of the time's share, for the extrapolated error of the chosen step
START_HALVINGS = 6  # a start step the scheme cannot take is halved, and the three runs start again
MAX_HALVINGS = 20  # the step is refused below T / (N0 2^MAX_HALVINGS)
FIRST_STEP_DIVISOR = 8  # the controller's first step is k0 / this (the step doubling's finest pilot is k0 / 4)


@dataclass(frozen=True)
class TimeEstimate:
    """What the three pilot runs at k, k/2, k/4 measured."""

    rate: float  # the observed order p
    error: float  # the error of the k/4 run
    times: np.ndarray  # the k/2 run's levels
    profile: np.ndarray  # the k/4 run's error at those levels


@dataclass(frozen=True)
class StepChoice:
    """The step the pilot runs on the start mesh choose, and what they measured."""

    k0: float  # the pilots' coarsest step (T / N0, halved while the scheme could not take it)
    k: float  # the chosen step, k0 / 2^j
    rate: float  # the observed order in k
    error: float  # the time error's bound at k
    times: np.ndarray  # the levels of the time error's profile
    profile: np.ndarray  # the time error at k on those levels
    growth: float  # the indicator's largest level over its level 0 (the first pilot)
    largest_t: float  # the time of that level
    pilot: PilotRun | None = None  # the run at k0 (the ingredients' changes are measured against it)
    adaptive: bool = False  # the run's step controller chooses the steps: k is its first step, error its tolerance


def norms(model: Model, comm: MPI.Comm) -> tuple[Callable[[np.ndarray], float], Callable[[np.ndarray], float]]:
    """||eps(v)|| and ||z|| of arrays on the model's spaces (collective; ||z|| is 0 without damage)."""
    V = model.u.function_space
    dv = fem.Function(V)
    eps = ufl.sym(ufl.grad(dv))
    fu = fem.form(ufl.inner(eps, eps) * ufl.dx)
    fz = dz = None
    if model.damage is not None:
        dz = fem.Function(model.damage.V)
        fz = fem.form(dz * dz * ufl.dx)

    def norm_u(a: np.ndarray) -> float:
        dv.x.array[:] = a
        return math.sqrt(max(comm.allreduce(fem.assemble_scalar(fu), op=MPI.SUM), 0.0))

    def norm_z(a: np.ndarray) -> float:
        if fz is None:
            return 0.0
        dz.x.array[:] = a
        return math.sqrt(max(comm.allreduce(fem.assemble_scalar(fz), op=MPI.SUM), 0.0))

    return norm_u, norm_z


def time_estimate(runs: list[PilotRun], order: int, comm: MPI.Comm) -> TimeEstimate:
    """From runs at k, k/2, k/4 on one mesh: the observed order (within [1/2, ``order``]) and the k/4 run's error,
    overall and at the k/2 levels (Richardson: the difference over 2^p - 1)."""
    norm_u, norm_z = norms(runs[0].model, comm)

    def diff(a: PilotRun, b: PilotRun) -> np.ndarray:
        out = []
        for j in range(len(a.t)):
            d = norm_u(a.u[j] - b.u[2 * j])
            if a.zeta:
                d += norm_z(a.zeta[j] - b.zeta[2 * j])
            out.append(d)
        return np.array(out)

    d1, d2 = diff(runs[0], runs[1]), diff(runs[1], runs[2])
    m1, m2 = float(d1.max()), float(d2.max())
    if m2 <= 1e-14 * max(1.0, m1):
        return TimeEstimate(float(order), 0.0, np.array(runs[1].t), np.zeros(len(d2)))
    p = math.log2(m1 / m2) if m1 > 0 else float(order)
    p = min(max(p, 0.5), float(order))
    return TimeEstimate(p, m2 / (2**p - 1), np.array(runs[1].t), d2 / (2**p - 1))


def first_pilot(pilot: Config, comm: MPI.Comm, geo: Geometry, tol: float) -> PilotRun:
    """The coarsest pilot, at k0 = T / N0 with the indicator (k0 halved while the scheme cannot take it): the first
    of the step doubling's three, and the ingredients' reference (:mod:`.ingredients`). ``tol`` names the tolerance
    in a refusal."""
    k0 = pilot.time.T / N0
    for _ in range(START_HALVINGS):
        try:
            return pilot_run(with_changes(pilot, step(k0)), comm, geo, indicator=True)
        except SolveFailure:
            k0 /= 2
    raise ToleranceError(tol, math.nan, 0, "time.k (no pilot step converged)")


def choose_step(pilot: Config, comm: MPI.Comm, geo: Geometry, order: int, share: float, tol: float,
                log: Callable[[str], None], first: PilotRun | None = None) -> StepChoice:
    """Step doubling of ``pilot`` on ``geo``, which also gives how the indicator evolves over the run; the largest
    T / n (n at least the pilots' coarsest T / k0) whose time error is within SAFETY times ``share``. ``tol`` names
    the tolerance in a refusal. ``first``: the coarsest pilot already run (:func:`first_pilot`), k0 its step."""
    k0 = pilot.time.T / N0 if first is None else first.model.cfg.time.k
    for _ in range(START_HALVINGS):
        try:
            pilots = [first if j == 0 and first is not None else
                      pilot_run(with_changes(pilot, step(k0 / 2**j)), comm, geo, indicator=(j == 0))
                      for j in range(3)]
            break
        except SolveFailure:
            k0 /= 2
            first = None
    else:
        raise ToleranceError(tol, math.nan, 0, "time.k (no pilot step converged)")
    est = time_estimate(pilots, order, comm)
    p, e_k4 = est.rate, est.error
    indicator = np.array(pilots[0].indicator)
    largest = int(np.argmax(indicator))
    growth = float(indicator[largest] / indicator[0]) if indicator[0] > 0 else math.inf
    log(f"start mesh: time error of k = {k0 / 4:g}: {e_k4:.3e} (order {p:.2f}); eta grows x{growth:.3g} "
        f"over the run")
    k4 = k0 / 4
    k = k0
    if e_k4 > 0:
        # the largest step T / n (n >= T / k0) whose extrapolated error is within SAFETY times the share
        k_max = k4 * (SAFETY * share / e_k4) ** (1.0 / p)
        n0 = round(pilot.time.T / k0)
        n = max(n0, math.ceil(pilot.time.T / k_max * (1.0 - 1e-12)))
        if n > n0 * 2**MAX_HALVINGS:
            raise ToleranceError(tol, e_k4, 0, "time.k")
        k = pilot.time.T / n
    scale = (k / k4) ** p if e_k4 > 0 else 0.0
    return StepChoice(k0, k, p, e_k4 * scale, est.times, est.profile * scale, growth, pilots[0].t[largest],
                      pilots[0])


def controller_step(pilot: Config, comm: MPI.Comm, geo: Geometry, order: int, share: float, tol: float,
                    log: Callable[[str], None], first: PilotRun | None = None) -> StepChoice:
    """The step of the run's controller (``time.adaptive``): its tolerance is ``share`` (the time's share of the
    tolerance, all of it: the controller keeps the sum of its steps' estimated errors within SHARE of it, see
    solver/run/adaptive.py), its first step k0 / FIRST_STEP_DIVISOR (the first ``order`` steps have no estimate).
    One pilot run at k0 = T / N0 on ``geo`` (halved while the scheme cannot take it) gives the indicator's growth
    over the run and is the ingredients' reference (``first``: that run already made). ``tol`` names the tolerance
    in a refusal."""
    run = first_pilot(pilot, comm, geo, tol) if first is None else first
    k0 = run.model.cfg.time.k
    indicator = np.array(run.indicator)
    largest = int(np.argmax(indicator))
    growth = float(indicator[largest] / indicator[0]) if indicator[0] > 0 else math.inf
    k = k0 / FIRST_STEP_DIVISOR
    log(f"start mesh: eta grows x{growth:.3g} over the run; the steps from the run's controller, time.tolerance = "
        f"{share:.3e}, first step {k:g}")
    return StepChoice(k0, k, float(order), share, np.array([0.0]), np.array([share]), growth, run.t[largest], run,
                      adaptive=True)


def restep(chosen: StepChoice, budget: float, T: float) -> StepChoice | None:
    """The largest T / n whose time error, scaled from ``chosen``'s by (k / chosen.k)^rate, is within ``budget``
    (what the space parts leave of the tolerance); None if none (budget <= 0). For the controller's step
    (``chosen.adaptive``): its tolerance made ``budget`` and its first step scaled alike."""
    if chosen.error <= budget:
        return chosen
    if budget <= 0.0:
        return None
    if chosen.adaptive:
        scale = budget / chosen.error
        return replace(chosen, k=chosen.k * scale ** (1.0 / chosen.rate), error=budget, profile=chosen.profile * scale)
    k = chosen.k * (budget / chosen.error) ** (1.0 / chosen.rate)
    n = math.ceil(T / k * (1.0 - 1e-12))
    k = T / n
    scale = (k / chosen.k) ** chosen.rate
    return replace(chosen, k=k, error=chosen.error * scale, profile=chosen.profile * scale)
