"""The time loop of Problem VP^hk (docs/model.md §3.6).

:meth:`Stepper.step` advances level n-1 -> n, with only data of level n-1 on the right-hand sides:
  1. memory: M_n from (u_{n-1}, zeta_{n-1}) -- level n-1 converged, so it is committed now;
  2. damage: zeta_{n-1} -> zeta_n (uses u_{n-1}, zeta_{n-1});
  3. displacement: u_n with M_n;
and returns the level's row (solver figures, diagnostics, timings). Level 0 is the elastic
contact problem with M_0 = 0 and zeta_0 = zeta0. :func:`run` is the loop around it:
output (sigma_n = A eps(u_n) + M_n), the CSV row, checkpoints and restart.

The scene decides what is built (:func:`build_model`): no damage solve without damage, no
history without memory, no contact term without a contact part.
"""

from __future__ import annotations

import dataclasses
import time
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path

from dolfinx import fem
from mpi4py import MPI
from petsc4py import PETSc

from . import checkpoint, formcache
from .config import Config, dumps
from .damage import Damage
from .diagnostics import DamageDiagnostics
from .errors import NonFiniteError, OutputError, SolveFailure
from .geometry import Geometry, build
from .io import CSV_COLUMNS, KRYLOV_COLUMNS, CSVWriter, on_rank0, write_text_atomic
from .linear import choose_linear
from .material import elasticity, lame
from .mechanics import Mechanics
from .memory import (
    History,
    MemorySource,
    OutOfPlaneSource,
    PlaneStrainHistory,
    QuadratureRule,
    all_finite,
    make_history,
    trapezoid_term,
)
from .outputs import Outputs

formcache.install()  # models are built many times per process (studies, tolerance runs): compiled forms kept


@dataclass
class Model:
    """Everything one scene builds: geometry, fields and the physics it switches on."""

    cfg: Config
    geo: Geometry
    u: fem.Function
    zeta: fem.Function | fem.Constant
    damage: Damage | None
    history: History | None
    rule: QuadratureRule
    mech: Mechanics
    u_prev: fem.Function | None = None  # u_{n-1} while level n is solved (time.order = 2: the extrapolation)
    linear: str = "auto"  # the linear solver solver.linear resolves to on this mesh (linear.choose_linear)

    @property
    def comm(self) -> MPI.Comm:
        return self.geo.comm


def build_model(cfg: Config, comm: MPI.Comm, geo: Geometry | None = None) -> Model:
    """Mesh, spaces and the physics terms the scene switches on (``geo``: a mesh already made, e.g. refined,
    instead of the scene's)."""
    geo = build(comm, cfg.mesh, cfg.boundaries, cfg.dim) if geo is None else geo
    mesh = geo.mesh
    disc = cfg.discretization
    V = fem.VectorFunctionSpace(mesh, ("CG", disc.u_degree))
    u = fem.Function(V, name="displacement")
    k, steps = cfg.time.k, cfg.time.steps
    dofs = V.dofmap.index_map.size_global * V.dofmap.index_map_bs
    linear = choose_linear(cfg.solver.linear, comm, geo.dim, dofs, cfg.solver.method)
    settings = dataclasses.replace(cfg.solver, linear=linear)  # cfg itself keeps the scene's value (restart's hash)
    damage = None
    if cfg.damage.enabled:
        Z = fem.FunctionSpace(mesh, ("CG", disc.zeta_degree))
        scheme = "cnab2" if cfg.time.order == 2 else cfg.solver.damage_scheme
        damage = Damage(Z, u, cfg.damage, k, cfg.solver.damage_quadrature_degree, cfg.solver.petsc_options,
                        linear, scheme, cfg.solver.rtol)
        zeta = damage.zeta
    else:
        zeta = fem.Constant(mesh, PETSc.ScalarType(cfg.damage.zeta0))
    rule = QuadratureRule(mesh, cfg.solver.quadrature_degree)
    mat = cfg.material
    history = None
    if cfg.memory.kernel != "none":
        lame_lambda, lame_mu = lame(mat.E, mat.nu, mat.model)
        source = MemorySource(rule, u, zeta, lame_lambda, lame_mu, cfg.memory.L)
        history = make_history(cfg.memory, rule, source, k, steps)
    implicit = None
    if history is not None and cfg.memory.rule == "trapezoid":
        implicit = trapezoid_term(history, zeta, lambda e: elasticity(e, mat.E, mat.nu, mat.model), cfg.memory.L)
    if history is not None and mat.model == "plane_strain":  # sigma_33 has a memory part too
        history = PlaneStrainHistory(history, make_history(cfg.memory, rule, OutOfPlaneSource(rule, source), k, steps))
    mech = Mechanics(geo, u, mat, cfg.boundaries, settings, history, implicit_term=implicit,
                     body_force=cfg.body_force)
    u_prev = fem.Function(V, name="displacement_previous") if history is not None and history.extrapolated else None
    return Model(cfg, geo, u, zeta, damage, history, rule, mech, u_prev, linear)


class Stepper:
    """Advances a model one time level at a time; each :meth:`step` returns the level's row."""

    def __init__(self, model: Model) -> None:
        self.model = model
        self.k = model.cfg.time.k
        self.damage_diagnostics = DamageDiagnostics(model.geo.mesh, model.damage, model.cfg.damage.zeta0)
        # the second-order scheme starts with one predictor-corrector step (Heun): AB2 and the extrapolation
        # need two past levels
        self.heun_start = model.cfg.time.order == 2 and (model.damage is not None or model.u_prev is not None)

    def step(self, n: int) -> dict:
        """Level n (n = 0: the initial elastic contact problem). Raises a SolveFailure that knows n and t."""
        model, t = self.model, n * self.k
        t0 = time.perf_counter()
        clipped, raw, dkrylov = 0, None, 0
        try:
            if n > 0 and model.history is not None:
                model.history.commit(n - 1)
            t1 = time.perf_counter()
            if n > 0 and model.damage is not None:
                dinfo = model.damage.step()
                clipped, raw, dkrylov = dinfo.clipped, (dinfo.raw_min, dinfo.raw_max), dinfo.krylov_iterations
            if n > 0 and model.u_prev is not None:
                self._extrapolated_memory(n)
            t2 = time.perf_counter()
            info = model.mech.solve(t)
            if n == 1 and self.heun_start:  # correct zeta_1 and M_1 with the predicted u_1, then solve again
                if model.damage is not None:
                    dinfo = model.damage.correct_first_step()
                    clipped, raw = dinfo.clipped, (dinfo.raw_min, dinfo.raw_max)
                    dkrylov += dinfo.krylov_iterations
                if model.u_prev is not None:
                    model.history.extrapolate(None)  # H(u_1, zeta_1), both predicted
                again = model.mech.solve(t)
                again.iterations += info.iterations
                again.linear_solves += info.linear_solves
                again.factorizations += info.factorizations
                again.krylov_iterations += info.krylov_iterations
                info = again
            self._check_finite()
        except SolveFailure as exc:
            raise exc.at(n, t) from None
        t3 = time.perf_counter()
        zmin, zmax = self.damage_diagnostics.zeta_range()
        raw = raw or (zmin, zmax)  # the range before clipping (level 0: the initial field)
        row = {
            "step": n, "t": t, "newton_iterations": info.iterations, "linear_solves": info.linear_solves,
            "factorizations": info.factorizations, "residual": info.residual,
            "krylov_iterations": info.krylov_iterations, "damage_krylov_iterations": dkrylov,
            **model.mech.diagnostics.row(),
            "zeta_min": zmin, "zeta_max": zmax, "zeta_raw_min": raw[0], "zeta_raw_max": raw[1], "zeta_clipped": clipped,
            "zeta_norm": self.damage_diagnostics.zeta_norm(),
        }
        t4 = time.perf_counter()
        row.update({"time_memory": t1 - t0, "time_damage": t2 - t1, "time_displacement": t3 - t2,
                    "time_diagnostics": t4 - t3})
        return row

    def _extrapolated_memory(self, n: int) -> None:
        """M_n = P_n + (k/2) g(0) H(u*, zeta_n), u* = 2 u_{n-1} - u_{n-2} (u_0 at n = 1); then u_prev = u_{n-1}.

        H(u*) comes from the strains of u_{n-1} (just committed) and u_{n-2} by linearity: no third product."""
        model = self.model
        model.history.extrapolate(model.u_prev.x.array if n >= 2 else None)
        model.u_prev.x.array[:] = model.u.x.array

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


def run(model: Model, outdir: Path | None = None, on_step: Callable[[dict], None] | None = None,
        restart: bool = False, sensors: tuple = ()) -> list[dict]:
    """Run the model's scene; write results to ``outdir`` (None: nothing written). Returns the rows.

    With ``restart``, the state is loaded from ``outdir``'s checkpoint and the run continues
    after it: the CSV keeps its rows up to the checkpoint, the XDMF series its levels up to
    it, and the new levels are appended. A write that fails (a full disk) stops the run with
    an OutputError that knows the step; what was written before stays readable.

    ``sensors``: objects with ``columns`` and ``sensor(row) -> dict`` that add their columns to
    every level's row and the CSV (e.g. the error estimates of a tolerance run); their time
    counts as diagnostics.
    """
    cfg, comm = model.cfg, model.comm
    steps = cfg.time.steps
    start, part, keep, keep_until = 0, 0, None, None
    if restart:
        ckpt = checkpoint.read(outdir, model)
        start, part, keep_until = ckpt.step + 1, ckpt.part, ckpt.t
        if comm.rank == 0:
            keep = _csv_lines_until(outdir / "timeseries.csv", ckpt.step)
    if outdir is not None:
        on_rank0(comm, lambda: write_text_atomic(outdir / "config.toml", dumps(cfg)))
    out = Outputs(model, cfg.material, cfg.output, outdir if cfg.output.xdmf else None, keep_until)
    columns = (CSV_COLUMNS + (KRYLOV_COLUMNS if model.linear == "iterative" else ()) + model.mech.diagnostics.columns
               + tuple(c for s in sensors for c in s.columns))
    csv = CSVWriter(outdir / "timeseries.csv", comm, keep=keep, columns=columns) if outdir is not None else None
    every_ckpt = cfg.output.checkpoint_every if outdir is not None else 0
    stepper = Stepper(model)
    rows: list[dict] = []
    finished = False
    try:
        for n in range(start, steps + 1):
            row = stepper.step(n)
            if sensors:
                t0 = time.perf_counter()
                for sensor in sensors:
                    row.update(sensor(row))
                row["time_diagnostics"] += time.perf_counter() - t0
            try:
                t0 = time.perf_counter()
                if writes_level(n, steps, cfg.output.every):
                    out.write(row["t"])
                row["time_output"] = time.perf_counter() - t0
                row["wall_time"] = sum(row[c] for c in ("time_memory", "time_damage", "time_displacement",
                                                        "time_diagnostics", "time_output"))
                rows.append(row)
                if csv is not None:
                    on_rank0(comm, lambda row=row: csv.write(row))
                if every_ckpt and n < steps and n % every_ckpt == 0:
                    out.flush()  # a checkpoint never runs ahead of the listed series
                    checkpoint.write(outdir, model, n, row["t"], part)
            except SolveFailure as exc:
                raise _located(exc, n, row["t"], cfg.time.k) from None
            if on_step is not None:
                on_step(row)
        try:
            out.close()
        except SolveFailure as exc:
            raise _located(exc, steps, steps * cfg.time.k, cfg.time.k) from None
        finished = True
    finally:
        out.close(quiet=not finished)
        if csv is not None:
            csv.close()
    return rows


def _located(exc: SolveFailure, n: int, t: float, k: float) -> SolveFailure:
    """The failure at level n, or, for a failed write that names its level (OutputError.level_t), at that level."""
    if isinstance(exc, OutputError) and exc.level_t is not None:
        return exc.at(round(exc.level_t / k), exc.level_t)
    return exc.at(n, t)


def _csv_lines_until(path: Path, step: int) -> list[str]:
    """The data lines of a timeseries.csv with step <= ``step``, as written (complete lines only)."""
    lines = path.read_text().splitlines(keepends=True)[1:] if path.exists() else []
    return [ln for ln in lines if ln.endswith("\n") and int(ln.split(",", 1)[0]) <= step]
