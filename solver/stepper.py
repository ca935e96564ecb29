"""The time loop of Problem VP^hk (MODEL.md section 3).

Per level n >= 1, with only data of level n-1 on the right-hand sides:
  1. damage: zeta_{n-1} -> zeta_n (uses u_{n-1}, zeta_{n-1});
  2. displacement: u_n with the memory M_n (formed at the end of step n-1);
  3. output of level n (sigma_n = A eps(u_n) + M_n);
  4. commit: M_{n+1} from (u_n, zeta_n) -- only after the step converged.
Level 0 is the elastic contact problem with M_0 = 0 and zeta_0 = zeta0.

The scene decides what is built: no damage solve without damage, no history
without memory, no contact term without a contact part.
"""

from __future__ import annotations

import time
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path

import dolfinx.fem.petsc  # noqa: F401  (fem.petsc)
import numpy as np
import ufl
from dolfinx import fem
from mpi4py import MPI
from petsc4py import PETSc

from . import checkpoint
from .config import Config, dumps
from .damage import Damage, DamageSolveError
from .geometry import Geometry, build
from .io import CellAverage, CSVWriter, XDMFWriter, merged_grids, von_mises_array, write_text_atomic
from .material import elasticity, lame, strain
from .mechanics import Mechanics, SolverError
from .memory import MemorySource, QuadratureRule, make_history, memory_source


class NonFiniteError(RuntimeError):
    """A field became NaN or inf."""


@dataclass
class Model:
    """Everything one scene builds: geometry, fields and the physics it switches on."""

    cfg: Config
    geo: Geometry
    u: fem.Function
    zeta: fem.Function | fem.Constant
    damage: Damage | None
    history: object | None
    rule: QuadratureRule
    mech: Mechanics

    @property
    def comm(self) -> MPI.Comm:
        return self.geo.comm


def build_model(cfg: Config, comm: MPI.Comm) -> Model:
    """Mesh, spaces and the physics terms the scene switches on."""
    gdim = 3 if cfg.material.model == "3d" else 2
    geo = build(comm, cfg.mesh, cfg.boundaries, gdim)
    mesh = geo.mesh
    V = fem.VectorFunctionSpace(mesh, ("CG", 1))
    u = fem.Function(V, name="displacement")
    k, steps = cfg.time.k, cfg.time.steps
    damage = None
    if cfg.damage.enabled:
        Z = fem.FunctionSpace(mesh, ("CG", 1))
        damage = Damage(Z, u, cfg.damage, k, cfg.solver.damage_quadrature_degree, cfg.solver.petsc_options,
                        cfg.solver.linear, cfg.solver.damage_scheme)
        zeta = damage.zeta
    else:
        zeta = fem.Constant(mesh, PETSc.ScalarType(cfg.damage.zeta0))
    rule = QuadratureRule(mesh, cfg.solver.quadrature_degree)
    history = None
    if cfg.memory.kernel != "none":
        lam, mu = lame(cfg.material.E, cfg.material.nu, cfg.material.model)
        source = MemorySource(rule, u, zeta, lam, mu, cfg.memory.L)
        history = make_history(cfg.memory, rule, source, k, steps)
    implicit = None
    if history is not None and cfg.memory.rule == "trapezoid":
        # the trapezoid's current-level term (k/2) g(0) (zeta_n Phi_L(A eps(u_n)), eps(w))
        def implicit(u_, w_, g0=history.g0, rule=rule):
            mat = cfg.material
            H = memory_source(u_, zeta, lambda e: elasticity(e, mat.E, mat.nu, mat.model), cfg.memory.L)
            half_k_g0 = fem.Constant(mesh, PETSc.ScalarType(0.5 * k * g0))  # not compiled into the form
            return half_k_g0 * ufl.inner(H, strain(w_)) * rule.dx
    mech = Mechanics(geo, cfg, u, history, implicit_term=implicit)
    return Model(cfg, geo, u, zeta, damage, history, rule, mech)


class Outputs:
    """The fields written to XDMF and the diagnostics of each level."""

    def __init__(self, model: Model, outdir: Path | None, part: int = 0, prefix: list | None = None) -> None:
        self.model = model
        mesh = model.geo.mesh
        d = mesh.geometry.dim
        T0 = fem.TensorFunctionSpace(mesh, ("DG", 0))
        self.stress = fem.Function(T0, name="stress")
        self.elastic_stress = fem.Function(T0, name="elastic_stress")
        S0 = fem.FunctionSpace(mesh, ("DG", 0))
        self.von_mises = fem.Function(S0, name="von_mises")
        # the paper's figures: memory balances the load, so "relaxes" / "not stress-free" are about A eps(u)
        self.von_mises_elastic = fem.Function(S0, name="von_mises_elastic")
        mat = model.cfg.material
        sig_el = elasticity(strain(model.u), mat.E, mat.nu, mat.model)
        sig = sig_el + model.history.M if model.history is not None else sig_el
        self.avg_el = CellAverage(sig_el, self.elastic_stress, model.rule.dx)
        self.avg = CellAverage(sig, self.stress, model.rule.dx)
        self.d = d
        Z = model.damage.zeta if model.damage is not None else None
        self.zeta = Z
        if Z is not None:  # ||zeta||^2 = zeta . M zeta, with the mass matrix assembled once
            z, xi = ufl.TrialFunction(Z.function_space), ufl.TestFunction(Z.function_space)
            self.mass = fem.petsc.assemble_matrix(fem.form(z * xi * ufl.dx))
            self.mass.assemble()
            self._mz = self.mass.createVecLeft()
        else:
            area = model.comm.allreduce(fem.assemble_scalar(fem.form(1.0 * ufl.dx(domain=mesh))), op=MPI.SUM)
            self._constant_norm = model.cfg.damage.zeta0 * float(np.sqrt(area))
        self.xdmf = None
        if outdir is not None and model.cfg.output.xdmf:
            funcs = [model.u] + ([Z] if Z is not None else []) + [self.stress, self.elastic_stress, self.von_mises,
                                                                  self.von_mises_elastic]
            self.xdmf = XDMFWriter(outdir, mesh, funcs, part=part, prefix=prefix)

    def update_cell_fields(self) -> None:
        self.avg_el.update()
        self.avg.update()
        n = self.von_mises.function_space.dofmap.index_map.size_local
        for tensor, scalar in ((self.stress, self.von_mises), (self.elastic_stress, self.von_mises_elastic)):
            scalar.x.array[:n] = von_mises_array(tensor.x.array[: n * self.d * self.d], self.d)
            scalar.x.scatter_forward()

    def zeta_range(self) -> tuple[float, float]:
        comm = self.model.comm
        if self.zeta is None:
            z0 = self.model.cfg.damage.zeta0
            return z0, z0
        n = self.zeta.function_space.dofmap.index_map.size_local
        a = self.zeta.x.array[:n]
        return (comm.allreduce(float(a.min()) if n else np.inf, op=MPI.MIN),
                comm.allreduce(float(a.max()) if n else -np.inf, op=MPI.MAX))

    def zeta_norm(self) -> float:
        if self.zeta is None:
            return self._constant_norm
        self.mass.mult(self.zeta.vector, self._mz)
        return float(np.sqrt(max(self._mz.dot(self.zeta.vector), 0.0)))

    def close(self) -> None:
        if self.xdmf is not None:
            self.xdmf.close()


def _check_finite(model: Model, n: int, t: float) -> None:
    bad = []
    if not np.all(np.isfinite(model.u.x.array)):
        bad.append("displacement")
    if model.damage is not None and not np.all(np.isfinite(model.damage.zeta.x.array)):
        bad.append("damage")
    if model.history is not None and not np.all(np.isfinite(model.history.M.x.array)):
        bad.append("memory")
    bad = model.comm.allreduce(bad, op=MPI.SUM)
    if bad:
        raise NonFiniteError(f"step {n}, t = {t:.6g}: non-finite values in {', '.join(sorted(set(bad)))}")


def writes_level(n: int, steps: int, every: int) -> bool:
    """Whether level n is written: every N-th level and the last; every=0: first and last."""
    if n == 0 or n == steps:
        return True
    return every > 0 and n % every == 0


def run(cfg: Config, outdir: Path | None, comm: MPI.Comm = MPI.COMM_WORLD,
        on_step: Callable[[dict], None] | None = None, model: Model | None = None,
        restart: bool = False) -> tuple[Model, list[dict]]:
    """Run the scene; write results to ``outdir`` (None: nothing written). Returns the model and the rows.

    With ``restart``, the state is loaded from ``outdir``'s checkpoint and the run continues
    after it: the CSV keeps its rows up to the checkpoint, the XDMF series its levels up to
    it, and the new levels go to a new data part.
    """
    model = model or build_model(cfg, comm)
    steps, k = cfg.time.steps, cfg.time.k
    start, part, keep, prefix = 0, 0, None, None
    if restart:
        ckpt = checkpoint.read(outdir, model)
        start, part = ckpt.step + 1, ckpt.part
        if comm.rank == 0:
            keep = _csv_lines_until(outdir / "timeseries.csv", ckpt.step)
            prefix = merged_grids(outdir, until=ckpt.t) if (outdir / "solution.xdmf").exists() else []
    if outdir is not None and comm.rank == 0:
        write_text_atomic(outdir / "config.toml", dumps(cfg))
    out = Outputs(model, outdir, part=part, prefix=prefix)
    csv = CSVWriter(outdir / "timeseries.csv", comm, keep=keep) if outdir is not None else None
    every_ckpt = cfg.output.checkpoint_every if outdir is not None else 0
    rows: list[dict] = []
    try:
        for n in range(start, steps + 1):
            t = n * k
            t0 = time.perf_counter()
            clipped, raw = 0, None
            try:
                if n > 0 and model.damage is not None:
                    dinfo = model.damage.step()
                    clipped, raw = dinfo.clipped, (dinfo.raw_min, dinfo.raw_max)
                t1 = time.perf_counter()
                info = model.mech.solve(t)
                _check_finite(model, n, t)
            except (SolverError, DamageSolveError, NonFiniteError) as exc:
                raise type(exc)(f"step {n}: {exc}") from None
            t2 = time.perf_counter()
            zmin, zmax = out.zeta_range()
            raw = raw or (zmin, zmax)  # the range before clipping (level 0: the initial field)
            row = {
                "step": n, "t": t, "newton_iterations": info.iterations, "linear_solves": info.linear_solves,
                "factorizations": info.factorizations, "residual": info.residual,
                "contact_force": model.mech.contact_force(), "contact_length": model.mech.contact_length(),
                "max_penetration": model.mech.max_penetration(), "zeta_min": zmin, "zeta_max": zmax,
                "zeta_raw_min": raw[0], "zeta_raw_max": raw[1], "zeta_clipped": clipped,
                "strain_norm": model.mech.strain_norm(), "zeta_norm": out.zeta_norm(),
            }
            t3 = time.perf_counter()
            if writes_level(n, steps, cfg.output.every) and out.xdmf is not None:
                out.update_cell_fields()
                out.xdmf.write(t)
            t4 = time.perf_counter()
            if model.history is not None and n < steps:
                model.history.commit(n)
            t5 = time.perf_counter()
            row.update({
                "time_damage": t1 - t0, "time_displacement": t2 - t1, "time_output": (t4 - t3) + (t3 - t2),
                "time_memory": t5 - t4, "wall_time": t5 - t0,
            })
            rows.append(row)
            if csv is not None:
                csv.write(row)
            if every_ckpt and n < steps and n % every_ckpt == 0:
                checkpoint.write(outdir, model, n, t, part)
            if on_step is not None:
                on_step(row)
    finally:
        out.close()
        if csv is not None:
            csv.close()
    return model, rows


def _csv_lines_until(path: Path, step: int) -> list[str]:
    """The data lines of a timeseries.csv with step <= ``step``, as written (complete lines only)."""
    lines = path.read_text().splitlines(keepends=True)[1:] if path.exists() else []
    return [ln for ln in lines if ln.endswith("\n") and int(ln.split(",", 1)[0]) <= step]
