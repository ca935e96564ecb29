"""The scene changes the planner tries: degrees, steps, the start mesh, the time order, the elastic level 0."""

from __future__ import annotations

from mpi4py import MPI

from solver.config import Config, from_dict, merge, to_dict
from solver.errors import ConfigError
from solver.mesh.geometry import build


def degrees(d: int) -> dict:
    """The changes of degree ``d`` for u and zeta alike: zeta's degree follows u's (docs/guide/accuracy.md)."""
    return {"discretization": {"u_degree": d, "zeta_degree": d}}


def step(k: float) -> dict:
    """The changes of time step ``k``."""
    return {"time": {"k": k}}


def merged(*changes: dict) -> dict:
    """One table of changes from several (the later win)."""
    out: dict = {}
    for c in changes:
        out = merge(out, c)
    return out


def with_changes(cfg: Config, *changes: dict) -> Config:
    """``cfg`` with ``changes``, validated (:meth:`Config.replace`)."""
    return cfg.replace(merged(*changes), label="accuracy plan")


def start_mesh(cfg: Config, comm: MPI.Comm) -> dict:
    """A coarse start for a built-in rectangle or box: about 4 cells across its shortest side (doubled until the
    boundary parts' ends fall on nodes); a gmsh mesh starts as it is. Returns the scene's changes."""
    if cfg.mesh.kind not in ("rectangle", "box"):
        return {}
    lo, hi = (list(c) for c in cfg.mesh.corners)
    sides = [b - a for a, b in zip(lo, hi)]
    h = min(sides) / 4
    for scale in (1, 2, 4, 8, 16):
        n = [max(1, round(side / h)) * scale for side in sides]
        start = {"mesh": dict(zip(("nx", "ny", "nz"), n))}
        try:
            build(comm, with_changes(cfg, start).mesh, cfg.boundaries, cfg.dim)
            return start
        except ConfigError:
            continue
    return {}


def time_order(cfg: Config) -> int:
    """2 where the scene allows the second-order scheme, else 1."""
    try:
        with_changes(cfg, {"time": {"order": 2}})
        return 2
    except ConfigError:
        return 1


def elastic(cfg: Config) -> Config:
    """The scene without memory and damage: its level 0 (the elastic contact problem) is the same."""
    data = to_dict(cfg)
    data["memory"] = {"kernel": "none"}
    data["damage"] = {"enabled": False}
    return from_dict(data, source=cfg.source)
