"""The solves the planner measures with: the t = 0 problem, a run to its level of largest indicator, and pilot runs
that keep every level. Each is a function that runs the solves and returns a record."""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Protocol

import numpy as np
import ufl
from dolfinx import fem
from mpi4py import MPI

from solver.config import Config
from solver.errors import NonFiniteError, SolveFailure
from solver.mesh.geometry import Geometry
from solver.mesh.transfer import interpolation_matrix
from solver.physics.estimator import estimator_for
from solver.physics.material import strain
from solver.physics.quadrature import all_finite
from solver.run.model import Model, build_model
from solver.run.scheme import level_scheme
from solver.run.stepper import levels

from .scene import degrees, elastic, step, with_changes

# a step Newton cannot take on a finer mesh is halved up to this many times
HALVINGS = 3
LEVEL0_LINEAR = "mumps"  # the planner's t = 0 solves' linear solver where the scene's is auto


@dataclass(frozen=True)
class LevelSolve:
    """A solved level on a mesh: the estimator's indicator eta, its cells' eta_K^2 and the dofs."""

    model: Model
    indicator: float
    cell_indicators: np.ndarray  # eta_K^2 of the owned cells
    dofs: int  # displacement dofs over all ranks
    strain_norm: float | None = None  # ||eps(u_0)|| (the t = 0 problem only)
    iterations: int = 0  # Newton's iterations (the t = 0 problem only)


def displacement_dofs(model: Model) -> int:
    """Displacement dofs over all ranks."""
    dofmap = model.u.function_space.dofmap
    return dofmap.index_map.size_global * dofmap.index_map_bs


def warm_start(model: Model, guess: Model | None) -> None:
    """Newton's start for ``model``'s level 0: ``guess``'s displacement (a solve on a coarser mesh that ``model``'s
    mesh refines, or on the same mesh at another degree) instead of zero. From zero, a stiff first contact takes
    plain Newton's steps and the compliance path; from the coarser solution it is in contact already and takes a few
    steps. 2-D only (the transfer's point location); elsewhere it starts from zero."""
    if guess is None or model.geo.dim != 2:
        return
    V = model.u.function_space
    bs = V.dofmap.index_map_bs
    owned = V.dofmap.index_map.size_local
    try:
        P = interpolation_matrix(guess.u.function_space, V.tabulate_dof_coordinates()[:owned, :2])
        found = True
    except ValueError:  # a point off this process's part of the other mesh
        found = False
    if not model.geo.comm.allreduce(found, op=MPI.LAND):  # all processes start from zero alike
        return
    coarse = guess.u.x.array.reshape(-1, bs)
    model.u.x.array[:owned * bs] = (P @ coarse).ravel()
    model.u.x.scatter_forward()


def strain_norm(model: Model) -> float:
    """||eps(u)|| of the model's displacement (one scalar assembly; collective)."""
    e = strain(model.u)
    local = fem.assemble_scalar(fem.form(ufl.inner(e, e) * ufl.dx))
    return math.sqrt(max(model.comm.allreduce(local, op=MPI.SUM), 0.0))


def solve_level0(cfg: Config, comm: MPI.Comm, geo: Geometry, guess: Model | None = None) -> LevelSolve:
    """The t = 0 problem of ``cfg`` on ``geo`` (without memory and damage, which level 0 does not touch); Newton
    starts from ``guess``'s solution where given (:func:`warm_start`). Only the displacement is solved: none of
    the time series' diagnostics (a row's contact traces, reactions and Gram matrix are made at their first use,
    which a t = 0 solve of the planner never is); ||eps(u_0)|| by one scalar assembly."""
    model = build_model(elastic(cfg), comm, geo)
    warm_start(model, guess)
    try:
        info, _ = level_scheme(model, model.scheme).displacement(0, 0.0, None)
    except SolveFailure as exc:
        raise exc.at(0, 0.0) from None
    if not comm.allreduce(bool(all_finite(model.u.x.array)), op=MPI.LAND):
        raise NonFiniteError(["displacement"])
    est = estimator_for(model)
    cells = est.cells()
    return LevelSolve(model, est.total(cells), cells, displacement_dofs(model), strain_norm(model), info.iterations)


def solve_largest_level(cfg: Config, comm: MPI.Comm, geo: Geometry) -> LevelSolve:
    """A run of ``cfg`` on ``geo`` (to its T): the level of largest indicator (scenes whose load starts at zero have
    nothing to adapt to at t = 0). A step Newton cannot take is halved (up to HALVINGS times)."""
    for halving in range(HALVINGS + 1):
        model = build_model(with_changes(cfg, step(cfg.time.k / 2**halving)), comm, geo)
        est = estimator_for(model)
        largest, largest_cells = -1.0, None
        try:
            for _ in levels(model, diagnostics=False):
                cells = est.cells()
                indicator = est.total(cells)
                if indicator > largest:
                    largest, largest_cells = indicator, cells
            return LevelSolve(model, largest, largest_cells, displacement_dofs(model))
        except SolveFailure:
            if halving == HALVINGS:
                raise
    raise AssertionError("unreachable: the last halving re-raises")


@dataclass
class PilotRun:
    """A run on a fixed mesh that kept u and zeta (and, if asked, the indicator) at every level."""

    model: Model
    t: list[float] = field(default_factory=list)
    u: list[np.ndarray] = field(default_factory=list)
    zeta: list[np.ndarray] = field(default_factory=list)
    indicator: list[float] = field(default_factory=list)
    newton: list[int] = field(default_factory=list)  # Newton's iterations per level


def pilot_run(cfg: Config, comm: MPI.Comm, geo: Geometry | None, indicator: bool = False,
              start: np.ndarray | None = None) -> PilotRun:
    """Run ``cfg`` on ``geo`` keeping every level's u and zeta, and the indicator with ``indicator``. ``start``: the
    solution of the t = 0 problem on ``geo`` at u's degree (this process's array, ghosts included), level 0's Newton
    start (one iteration instead of a cold first contact); ignored where its size differs on any process."""
    model = build_model(cfg, comm, geo)
    if comm.allreduce(start is not None and start.size == model.u.x.array.size, op=MPI.LAND):
        model.u.x.array[:] = start
    est = estimator_for(model) if indicator else None
    out = PilotRun(model)
    for row in levels(model, diagnostics=False):
        out.t.append(row["t"])
        out.newton.append(row["newton_iterations"])
        out.u.append(model.u.x.array.copy())
        if model.damage is not None:
            out.zeta.append(model.damage.zeta.x.array.copy())
        if est is not None:
            out.indicator.append(est.total())
    return out


class SpaceProbe(Protocol):
    """What u's mesh is solved and judged with: the solve of a degree on a mesh, and the indicator's growth
    over the run, by which C eta of that solve is multiplied (``factor``, at least 1)."""

    growth: float

    @property
    def factor(self) -> float: ...

    def solve(self, degree: int, comm: MPI.Comm, geo: Geometry, guess: Model | None = None) -> LevelSolve: ...


class AtLevel0:
    """The t = 0 problem of ``scene``, its indicator times the ``growth`` measured over the run on the start mesh."""

    def __init__(self, scene: Config, growth: float) -> None:
        self.scene, self.growth = scene, growth
        self._at: dict[int, Config] = {}  # the scene per degree, validated once

    @property
    def factor(self) -> float:
        return max(self.growth, 1.0)

    def solve(self, degree: int, comm: MPI.Comm, geo: Geometry, guess: Model | None = None) -> LevelSolve:
        if degree not in self._at:
            # MUMPS where the scene leaves the solver to auto: a t = 0 solve is one factorization, which MUMPS made
            # in 0.57x the time of PETSc's Cholesky (P2, 8,192 cells, serial, two alternated rounds)
            linear = {"solver": {"linear": LEVEL0_LINEAR}} if self.scene.solver.linear == "auto" else {}
            self._at[degree] = elastic(with_changes(self.scene, degrees(degree), linear))
        return solve_level0(self._at[degree], comm, geo, guess)


class AtLargestLevel:
    """Coarse-step runs of ``scene`` to its level of largest indicator, which counts as it is (growth 1)."""

    growth = 1.0

    def __init__(self, scene: Config) -> None:
        self.scene = scene

    @property
    def factor(self) -> float:
        return 1.0

    def solve(self, degree: int, comm: MPI.Comm, geo: Geometry, guess: Model | None = None) -> LevelSolve:
        return solve_largest_level(with_changes(self.scene, degrees(degree)), comm, geo)
