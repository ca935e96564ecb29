"""The Python interface: load or build a scene, change it, run it, get arrays back.

The same scenes, checks and results as ``python -m solver run``, without strings::

    from solver import api
    cfg = api.load("configs/example1.toml").replace({"time": {"k": 0.02}})
    res = api.run(cfg)                        # in memory; api.run(cfg, "results/x") also writes the files
    res.series["contact_force"]               # one numpy array per timeseries.csv column, one entry a level
    res.fields["damage"]                      # the final level's fields at the mesh nodes (input order)
    res.contact["bottom"]["pressure"]         # the contact profile of part bottom, a row a written level

A change that a scene file would refuse raises the same one-line :class:`solver.errors.ConfigError`.
``api.run(cfg, tolerance=1e-2)`` plans mesh, degree and step as ``solver run --tolerance`` does.
A sweep of the compliance, the material constants or the memory truncation compiles no new form (they enter the
forms as ``fem.Constant``); the form compiler's build log stays off stderr unless ``api.compiler_output(True)``.
Every rank of a communicator calls :func:`run` with the same scene; every rank gets the same
series and the same (gathered) fields.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
from mpi4py import MPI

from solver.config import Config, from_dict, load
from solver.io.layout import API, PROFILE_COLUMNS, ResultsDir, timeseries_columns
from solver.io.xdmf import DolfinxRows, dolfinx_layout
from solver.post.results import contact_levels, read_contact, read_csv
from solver.post.results import read_results as read_dir
from solver.run import formcache
from solver.run.formcache import show_compiler_output as compiler_output

__all__ = ["Config", "Results", "compiler_output", "load", "read", "read_contact", "run", "scene"]


@dataclass
class Results:
    """A run's time series and final fields.

    ``series``: one array per column of ``timeseries.csv`` (``step``, ``t``, ``contact_force``, ``zeta_min``, ...),
    one entry a level. ``fields``: the last written level's node fields (``displacement`` as (nodes, dim),
    ``damage`` as (nodes,)) at ``points`` in the mesh's input order, the same on every rank.
    ``directory``: where the files went (None: in memory). ``model``: the live dolfinx objects of an in-memory
    run (``model.u``, ``model.zeta``), for post-processing with dolfinx/UFL; None when read from files.
    ``plan``: what a tolerance chose (:class:`solver.run.accuracy.Plan`: ``degree``, ``order``, ``k``,
    ``summary()`` as in plan.json); None without a tolerance or when read from files.
    ``contact``: the contact profile at every written level, per contact part (:func:`read_contact`'s arrays:
    ``step`` and ``t`` a value a level; ``s``, ``x``, ``y``, ``z``, ``gap``, ``u_normal``, ``penetration``,
    ``pressure`` a row a level, a column a node along the part); {} without contact.
    """

    series: dict[str, np.ndarray]
    fields: dict[str, np.ndarray]
    points: np.ndarray
    directory: Path | None = None
    model: Any = field(default=None, repr=False)
    plan: Any = field(default=None, repr=False)
    contact: dict[str, dict[str, np.ndarray]] = field(default_factory=dict, repr=False)

    @property
    def columns(self) -> tuple[str, ...]:
        """The time series' column names, in the CSV's order."""
        return tuple(self.series)

    def table(self, *columns: str) -> np.ndarray:
        """The chosen columns (default: all) as one 2-D array, a row a level: a table without pandas."""
        names = columns or self.columns
        return np.column_stack([self.series[c] for c in names])


def scene(data: dict | None = None, source: str = "<python>", base: str | Path | None = None) -> Config:
    """A scene built in Python from a TOML-shaped dict (``{}``: the paper's Example 1), validated as a file is.

    ``base``: the directory relative paths (``mesh.file``) are read from (default: the current one).
    """
    return from_dict({} if data is None else data, source=source, base=Path(base).resolve() if base else None)


def run(cfg: Config, output: str | Path | None = None, overwrite: bool = False, comm: Any = None,
        on_step: Any = None, tolerance: float | None = None) -> Results:
    """Run ``cfg``; with ``output``, write the results directory as ``solver run --output`` does.

    ``overwrite``: replace earlier results in ``output`` (else a
    :class:`solver.io.layout.OutputDirectoryError`, a UsageError, as the CLI refuses).
    ``tolerance``: as ``solver run --tolerance`` (``accuracy.tolerance``, also taken from the scene): the solver
    chooses mesh, degree and step first (the same plan and results as the CLI; plan.json and mesh.xdmf with
    ``output``). ``on_step(row)``: called after each level (a progress bar). ``comm``: default MPI.COMM_WORLD.
    """
    from solver.io.launch import launch
    from solver.io.results import run as run_model

    comm = MPI.COMM_WORLD if comm is None else comm
    if tolerance is not None:
        cfg = cfg.replace({"accuracy": {"tolerance": tolerance}}, label="tolerance")
    outdir = None if output is None else Path(output)
    formcache.install()  # compiled forms kept in memory across the runs of a sweep, and compiled quietly
    start = launch(cfg, comm, outdir, overwrite, wording=API)
    profile = _ProfileKeeper(start.model, on_step)
    rows = run_model(start.model, outdir, on_step=profile.level, sensors=start.sensors)
    series = {c: np.array([r[c] for r in rows], dtype=float) for c in timeseries_columns(start.model, start.sensors)}
    points, fields = final_fields(start.model)
    return Results(series, fields, points, outdir, start.model, start.plan, profile.arrays())


class _ProfileKeeper:
    """The contact profile of every written level, kept in memory as contact.csv would hold it (every rank gets it)."""

    def __init__(self, model: Any, on_step: Any) -> None:
        from solver.run.stepper import writes_level

        self.model, self.on_step, self.writes = model, on_step, writes_level
        self.traces = model.mech.diagnostics.traces
        self.levels: dict[tuple[int, str], dict[str, np.ndarray]] = {}

    def level(self, row: dict) -> None:
        time = self.model.cfg.time
        if self.traces is not None and self.writes(row["step"], time.steps, self.model.cfg.output.every):
            # the traces as the level's diagnostics left them (as the contact.csv writer takes them)
            parts = self.model.comm.bcast(self.traces.profile(), root=0)  # collective; rank 0 holds the rows
            for name, rows in parts:
                cols = dict(zip(PROFILE_COLUMNS[3:], rows.T))
                cols["t"] = np.full(len(rows), row["t"])
                self.levels[(row["step"], name)] = cols
        if self.on_step is not None:
            self.on_step(row)

    def arrays(self) -> dict[str, dict[str, np.ndarray]]:
        return contact_levels(self.levels) if self.levels else {}


def read(directory: str | Path) -> Results:
    """The results a run wrote to ``directory`` (timeseries.csv and the last level of solution.xdmf)."""
    directory = Path(directory)
    rows = read_csv(ResultsDir(directory).timeseries)
    series = {c: np.array([r[c] for r in rows]) for c in rows[0]} if rows else {}
    res = read_dir(directory)
    last = res["times"][-1]
    dim = res["geometry"].shape[1]  # the writer keeps the mesh's geometric dimension
    fields = {}
    for name, levels in res["fields"].items():
        if last in levels:
            v = levels[last]
            fields[name] = v[:, :dim] if name == "displacement" else (v[:, 0] if v.ndim == 2 and v.shape[1] == 1 else v)
    return Results(series, fields, res["geometry"][:, :dim], directory, contact=read_contact(directory))


def final_fields(model: Any) -> tuple[np.ndarray, dict[str, np.ndarray]]:
    """The model's displacement and damage at the mesh nodes (P1 values; higher degrees interpolated to P1, as the
    writer does), gathered in input order on every rank: (points, {name: values})."""
    mesh = model.geo.mesh
    layout, rows = dolfinx_layout(mesh), DolfinxRows(mesh)
    comm = mesh.comm
    keys = np.concatenate(comm.allgather(layout.node_keys))
    order = np.argsort(keys, kind="stable")
    gathered = lambda a: np.concatenate(comm.allgather(np.ascontiguousarray(a)))[order]  # noqa: E731
    out = {"displacement": gathered(rows.rows(_p1(model.u)))}
    if model.damage is not None:
        out["damage"] = gathered(rows.rows(_p1(model.damage.zeta)))[:, 0]
    return gathered(layout.points), out


def _p1(f: Any) -> Any:
    """``f`` if it is P1, else its interpolant in P1 (the values the XDMF writer writes)."""
    from dolfinx import fem

    el = f.function_space.ufl_element()
    if el.degree() == 1:
        return f
    mesh = f.function_space.mesh
    V1 = (fem.VectorFunctionSpace(mesh, ("CG", 1), dim=el.value_shape()[0]) if el.value_shape()
          else fem.FunctionSpace(mesh, ("CG", 1)))
    out = fem.Function(V1)
    out.interpolate(f)
    return out
