"""Starting a run in a results directory, the same from the command line and from :mod:`solver.api`: the directory
prepared (:func:`solver.io.layout.prepare`), a restart's scene checked against its checkpoint, and with
``accuracy.tolerance`` the plan made first (docs/guide/accuracy.md) and written (plan.json, mesh.xdmf).

:func:`launch` returns what :func:`solver.io.results.run` runs: the scene, its model and the error sensor of a
plan. Nothing is made in the directory before the plan is accepted: a refused tolerance leaves nothing behind.
"""

from __future__ import annotations

import dataclasses
import json
import logging
import tomllib
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING

import h5py
from dolfinx.io import XDMFFile
from mpi4py import MPI

from solver.config import Config, from_dict, to_dict
from solver.errors import ConfigError, UsageError, show
from solver.io.checkpoint import scene_hash
from solver.io.files import on_rank0, write_text_atomic
from solver.io.layout import CLI, ResultsDir, Wording, prepare
from solver.run import formcache
from solver.run.model import Model, build_model

if TYPE_CHECKING:  # the planner is imported only by a run with a tolerance (start-up: docs/benchmarks/speed.md)
    from solver.run.accuracy import Plan

log = logging.getLogger("solver")


@dataclass
class Launched:
    """What a run starts from: the scene as run (a tolerance's planned one), its model, the plan (None without a
    tolerance) and the sensors whose columns join the time series."""

    config: Config
    model: Model
    plan: Plan | None
    sensors: tuple


def launch(cfg: Config, comm: MPI.Comm, outdir: Path | None, overwrite: bool = False, restart: bool = False,
           overrides: list[str] | tuple[str, ...] = (), wording: Wording = CLI,
           info: Callable[..., None] = log.info) -> Launched:
    """Prepare ``outdir`` (None: a run in memory) and build the model of ``cfg``, planned first when it sets
    ``accuracy.tolerance``. ``overrides``: the ``--set`` strings, refused where they contradict a tolerance.
    ``info``: where the planner's progress goes. Refusals are :class:`solver.errors.UsageError`."""
    if outdir is not None:
        cfg = directed(cfg, outdir)
    if cfg.accuracy.enabled:
        return _planned(cfg, comm, outdir, overwrite, restart, overrides, wording, info)
    if restart:
        same_scene(comm, cfg, outdir)  # before anything is built
    model = build_model(cfg, comm)  # geometry problems are found before any file is made
    if outdir is not None:
        prepare(comm, outdir, overwrite, restart, wording=wording)
    return Launched(cfg, model, None, ())


def directed(cfg: Config, outdir: str | Path) -> Config:
    """``cfg`` with ``output.directory`` = ``outdir``, so that the resolved config.toml written there names the
    directory the run wrote (``solver run DIR/config.toml`` writes to DIR again, not to the scene's directory)."""
    if cfg.output.directory == str(outdir):
        return cfg
    document = None
    if cfg.document is not None:
        document = dict(cfg.document)
        document["output"] = {**document.get("output", {}), "directory": str(outdir)}
    return dataclasses.replace(cfg, output=dataclasses.replace(cfg.output, directory=str(outdir)), document=document)


def _planned(cfg: Config, comm: MPI.Comm, outdir: Path | None, overwrite: bool, restart: bool,
             overrides: list[str] | tuple[str, ...], wording: Wording, info: Callable[..., None]) -> Launched:
    """Plan the scene for its tolerance, then prepare the directory, build the planned model and its error sensor,
    and write plan.json and mesh.xdmf."""
    from solver.run.accuracy import ErrorSensor, contradicting
    from solver.run.accuracy import plan as make_plan

    clash = contradicting(list(overrides))
    if clash:
        raise UsageError(f"--set {clash[0]}: contradicts the tolerance (with accuracy.tolerance the solver chooses "
                         "the mesh size, the step, the degree and the order); drop one of them")
    if outdir is not None:
        prepare(comm, outdir, overwrite, restart, dry=True, wording=wording)
    info("tolerance %g: choosing degree, mesh and step", cfg.accuracy.tolerance)
    formcache.install()  # the planner builds a dozen models: keep their compiled forms in memory
    plan = make_plan(cfg, comm, log=info)
    if outdir is not None:
        prepare(comm, outdir, overwrite, restart, wording=wording)  # only now: a refused tolerance makes nothing
    cfg = plan.config
    if restart:
        same_scene(comm, cfg, outdir)
    model = build_model(cfg, comm, plan.geo)
    if not restart:
        plan.warm_start(model)  # level 0 is the planner's last t = 0 problem: Newton starts at its solution
    sensors = (ErrorSensor(model, plan),)
    if outdir is not None:
        write_plan(comm, outdir, plan, model)
    return Launched(cfg, model, plan, sensors)


def write_plan(comm: MPI.Comm, outdir: Path, plan: Plan, model: Model) -> None:
    """plan.json (what the tolerance chose and why) and the chosen mesh with its boundary tags (mesh.xdmf)."""
    files = ResultsDir(outdir)
    summary = plan.summary()
    summary["parts"] = model.geo.tags
    on_rank0(comm, lambda: write_text_atomic(files.plan, json.dumps(summary, indent=1) + "\n"))
    with XDMFFile(comm, str(files.plan_mesh), "w") as f:
        f.write_mesh(model.geo.mesh)
        model.geo.mesh.topology.create_connectivity(model.geo.dim - 1, model.geo.dim)
        f.write_meshtags(model.geo.facet_tags)


def same_scene(comm: MPI.Comm, cfg: Config, outdir: Path) -> None:
    """Refuse a restart whose scene differs from the checkpoint's, naming the first key that differs."""
    problem = None
    if comm.rank == 0:
        files = ResultsDir(outdir)
        try:
            with h5py.File(files.checkpoint, "r") as h5:
                stored = h5.attrs["scene"]
        except (OSError, KeyError):
            stored = None  # missing or unreadable: prepare() and checkpoint.read say so
        if stored is not None and stored != scene_hash(cfg):
            problem = f"--restart: the scene differs from the one that wrote {files.checkpoint}"
            key = first_difference(cfg, files.config)
            problem += (f" at {key}" if key else "") + " (only [output] may change)"
    problem = comm.bcast(problem, root=0)
    if problem:
        raise UsageError(problem)


def first_difference(cfg: Config, written: Path) -> str | None:
    """The first key (dotted, [output] left out) where cfg differs from the resolved scene in ``written``, with both
    values; None if that file is missing or unreadable."""
    try:
        old = tomllib.loads(written.read_text())
    except (OSError, ValueError):
        return None
    try:  # its tables from files (tables/) read back, as cfg holds them
        old = to_dict(from_dict(old, source=str(written), base=written.parent))
    except ConfigError:
        pass  # compared as written

    def walk(a, b, prefix: str) -> str | None:
        if isinstance(a, dict) and isinstance(b, dict):
            for key in list(a) + [k for k in b if k not in a]:
                if prefix + key == "output":
                    continue
                found = walk(a.get(key), b.get(key), f"{prefix}{key}.")
                if found:
                    return found
            return None
        if a != b:
            return f"{prefix.rstrip('.')} = {show(a)} (the checkpoint's run had {show(b)})"
        return None

    return walk(to_dict(cfg), old, "")
