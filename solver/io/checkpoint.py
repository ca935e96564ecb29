"""Checkpoints: the whole state of a run at a time level, for ``run --restart``.

Every value is stored against the physical coordinates of its dof (mesh nodes for the
P1 fields, quadrature points for the history), gathered from the owned dofs of all
ranks and sorted. A restart looks its own dofs up by coordinates, so it does not depend
on the partition (which is not reproducible from one parallel launch to the next) nor on
the number of ranks. Stored: u, zeta, every history array (M_n of the level: the next
step commits M_{n+1} first), the displacement solver's carried vectors (so the first step
after a restart does the same arithmetic), the step, and a hash of the scene (output
settings excluded) so that a restart cannot silently continue another problem. Rank 0
writes with h5py to a temporary name and renames.
"""

from __future__ import annotations

import hashlib
import os
from dataclasses import dataclass, replace
from pathlib import Path

import h5py
import numpy as np
import ufl
from dolfinx import fem
from mpi4py import MPI

from solver.config import Config, OutputConfig
from solver.config.scene import fingerprint
from solver.errors import ConfigError
from solver.io import layout
from solver.io.files import on_rank0

NAME = layout.CHECKPOINT
FORMAT = 1  # the layout of checkpoint.h5 this version writes and reads; raised when a change makes old files unreadable


_HASHED: list[tuple[Config, str]] = []  # the last scene hashed and its hash (a Config is frozen)


def scene_hash(cfg: Config) -> str:
    """Hash of everything that defines the solution (not where or how often it is written). The last scene's hash
    is kept: a run writes a checkpoint every ``checkpoint_every`` levels, and the scene's text takes tens of ms."""
    if _HASHED and _HASHED[0][0] is cfg:
        return _HASHED[0][1]
    text = fingerprint(replace(cfg, output=OutputConfig(), source=""))
    digest = hashlib.sha256(text.encode()).hexdigest()
    _HASHED[:] = [(cfg, digest)]
    return digest


def _keys(coords: np.ndarray) -> np.ndarray:
    """Sortable keys of points (rounded to 1e-10)."""
    c = np.ascontiguousarray(np.round(coords, 10))
    return c.view([(f"x{i}", c.dtype) for i in range(c.shape[1])]).ravel()


def _order(coords: np.ndarray) -> np.ndarray:
    """The order of the points by their :func:`_keys` (x, then y, then z, rounded to 1e-10): ``np.lexsort`` on the
    columns, which sorts distinct points as ``np.argsort(_keys(coords))`` does, several times faster than the
    structured comparison (figures: docs/developer/design-notes.md)."""
    c = np.round(coords, 10)
    return np.lexsort(c.T[::-1])


BLOCK = 65536  # rows a block of a sorted write: 1.5 MB of coordinates and up to 5 MB of values in 3-D


def _write_sorted(h5, name: str, coords: np.ndarray, values: np.ndarray) -> None:
    """``NAME/coords`` and ``NAME/values`` in the order of the points (:func:`_order`), written a block of rows at a
    time: no sorted copy of the whole field beside it (M alone is 40 MiB at 311,469 dofs in 3-D)."""
    order = _order(coords)
    for key, data in (("coords", coords), ("values", values)):
        ds = h5.create_dataset(f"{name}/{key}", shape=data.shape, dtype=data.dtype)
        for start in range(0, len(order), BLOCK):
            rows = order[start: start + BLOCK]
            ds[start: start + len(rows)] = data[rows]


def _point_coordinates(rule, Q, gdim: int) -> np.ndarray:
    """The coordinates of the quadrature space Q's points (points, gdim), ghosts included: evaluated into one array
    and laid out by Q's own dofmap (no space of their own, no second copy: 13 MiB each at 311,469 dofs in 3-D)."""
    npts = rule.points.shape[0]
    values = fem.Expression(ufl.SpatialCoordinate(rule.mesh), rule.points).eval(rule.cells)  # (cell, point * gdim)
    dofs = Q.dofmap.list.array.reshape(-1, npts)[: len(rule.cells)].ravel()
    size = Q.dofmap.index_map.size_local + Q.dofmap.index_map.num_ghosts
    if np.array_equal(dofs, np.arange(size)):
        return values.reshape(-1, gdim)
    out = np.empty((size, gdim))
    out[dofs] = values.reshape(-1, gdim)
    return out


@dataclass
class _Field:
    coords: np.ndarray  # dof coordinates (owned first)
    rows: np.ndarray  # values, one row per dof
    owned: int
    assign: object  # callable(rows) writing loaded values back


def _fields(model, clock=None) -> dict[str, _Field]:
    """Everything a checkpoint holds, each with its dof coordinates and how to write it back (``clock``: an
    adaptive run's step controller, whose past values are zeta- and memory-shaped arrays)."""
    V = model.u.function_space
    nv = V.dofmap.index_map.size_local
    cv = V.tabulate_dof_coordinates()

    def setter(target: np.ndarray):
        def assign(rows: np.ndarray) -> None:
            target[...] = rows.reshape(target.shape)
        return assign

    out = {"u": _Field(cv, model.u.x.array.reshape(len(cv), -1), nv, setter(model.u.x.array))}
    if model.u_prev is not None:  # time.order = 2: u_{n-1} for the extrapolation
        up = model.u_prev.x.array
        out["u_prev"] = _Field(cv, up.reshape(len(cv), -1), nv, setter(up))
    mech = model.mech.state()  # owned parts of PETSc vectors
    for k, v in mech.items():
        out[f"mech/{k}"] = _Field(cv[:nv], v.reshape(nv, -1), nv, lambda rows, k=k: model.mech.restore_vector(k, rows))
    if model.damage is not None:
        Z = model.damage.V
        cz = Z.tabulate_dof_coordinates()
        z = model.damage.zeta.x.array
        nz = Z.dofmap.index_map.size_local
        out["zeta"] = _Field(cz, z.reshape(len(cz), 1), nz, setter(z))
    if model.damage is not None:
        for k, v in model.damage.state().items():  # owned parts of PETSc vectors
            out[f"damage/{k}"] = _Field(cz[:nz], v.reshape(nz, 1), nz,
                                        lambda rows, k=k: model.damage.restore(k, rows))
    if model.history is not None:
        Q = model.history.M.function_space
        rule = model.history.rule
        gdim = model.geo.mesh.geometry.dim
        cq = _point_coordinates(rule, Q, gdim)
        nq = Q.dofmap.index_map.size_local
    if clock is not None:
        for name, (space, a) in clock.arrays().items():
            c, n = {"u": (cv, nv), "zeta": (cz, nz), "memory": (cq, nq)}[space]
            out[f"clock/{name}"] = _Field(c, a.reshape(len(c), -1), n, setter(a))
    if model.history is not None:
        for k, v in model.history.state().items():
            out[f"history/{k}"] = _Field(cq, v.reshape(len(cq), -1), nq, setter(v))
    return out


def write(directory: Path, model, step: int, t: float, part: int, clock=None) -> None:
    """Write the checkpoint of level ``step`` (collective; rank 0 writes); ``clock``: an adaptive run's
    :class:`solver.run.adaptive.StepController`, whose step history and past levels it keeps too.

    Streamed: one field at a time is gathered to rank 0, sorted and written a block of rows at a time, so that the
    write holds at most one field's gathered copy beside the state and no sorted copy of it (one process gathers
    nothing: its own arrays are written)."""
    comm = model.comm
    fields = _fields(model, clock)
    path = Path(directory) / NAME
    tmp = path.with_name(NAME + ".tmp")
    h5, error = None, None
    if comm.rank == 0:
        try:
            h5 = h5py.File(tmp, "w")
            h5.attrs.update({"format": FORMAT, "step": step, "t": t, "scene": scene_hash(model.cfg), "part": part,
                             **{f"mech_{k}": v for k, v in model.mech.scalars().items()},
                             **({f"damage_{k}": v for k, v in model.damage.scalars().items()} if model.damage else {}),
                             **({f"clock_{k}": v for k, v in clock.scalars().items()} if clock else {})})
        except Exception as exc:  # noqa: BLE001  (reported after the collective gathers below)
            error = exc
    for name, f in fields.items():
        mine = (f.coords[: f.owned], f.rows[: f.owned])
        parts = comm.gather(mine, root=0) if comm.size > 1 else [mine]
        if comm.rank != 0 or error is not None:
            continue
        try:
            coords = parts[0][0] if len(parts) == 1 else np.concatenate([p[0] for p in parts])
            values = parts[0][1] if len(parts) == 1 else np.concatenate([p[1] for p in parts])
            del parts
            _write_sorted(h5, name, coords, values)
            del coords, values
        except Exception as exc:  # noqa: BLE001
            error = exc

    def save() -> None:
        try:
            if error is not None:
                raise error
            h5.close()
            with open(tmp, "rb") as fh:
                os.fsync(fh.fileno())
        except Exception as exc:  # a full disk: the previous checkpoint stays as it was
            if h5 is not None and h5.id.valid:
                try:
                    h5.close()
                except Exception:  # noqa: BLE001
                    pass
            tmp.unlink(missing_ok=True)
            if isinstance(exc, OSError):
                raise exc from None
            raise OSError(f"{NAME}: {exc}") from exc
        os.replace(tmp, path)

    on_rank0(comm, save)


@dataclass
class Checkpoint:
    """What a restart needs: the level, its time, and which data part comes next."""

    step: int
    t: float
    part: int


def read(directory: Path, model, clock=None) -> Checkpoint:
    """Load the checkpoint into the model (u, zeta, history, solver state) and ``clock`` (an adaptive run's step
    controller); refuse a mismatch clearly."""

    comm = model.comm
    path = Path(directory) / NAME
    if not path.exists():
        raise ConfigError(f"--restart: {path} does not exist (was the run started with output.checkpoint_every > 0?)")
    with h5py.File(path, "r") as h5:
        a = dict(h5.attrs)
        version = int(a.get("format", 1))  # files from before the attribute have format 1's layout
        if version != FORMAT:
            raise ConfigError(f"--restart: {path} has checkpoint format {version}, this solver reads format {FORMAT} "
                              f"({'a newer' if version > FORMAT else 'an older'} version of the solver wrote it); "
                              "continue it with that version, or start the run again without --restart")
        if a["scene"] != scene_hash(model.cfg):
            raise ConfigError(f"--restart: the scene differs from the one that wrote {path} (only [output] may change), "
                              "or another version of the solver wrote it")
        fields, loaded, ok = _fields(model, clock), {}, True
        missing = [name for name in fields if f"{name}/coords" not in h5]
        if missing:
            raise ConfigError(f"--restart: {path} lacks {', '.join(missing)} (written by another version of the "
                              "solver?); start the run again without --restart")
        for name, f in fields.items():
            ref = _keys(h5[f"{name}/coords"][...])
            mine = _keys(f.coords)
            idx = np.clip(np.searchsorted(ref, mine), 0, max(len(ref) - 1, 0))
            ok &= bool(len(ref)) and bool(np.all(ref[idx] == mine))
            loaded[name] = idx
        if not comm.allreduce(ok, op=MPI.LAND):
            raise ConfigError(f"--restart: the mesh differs from the one in {path}")
        for name, f in fields.items():
            f.assign(h5[f"{name}/values"][...][loaded[name]])
    try:
        model.mech.restore_scalars({k.removeprefix("mech_"): v for k, v in a.items() if k.startswith("mech_")})
        if model.damage is not None:
            model.damage.restore_scalars({k.removeprefix("damage_"): v for k, v in a.items()
                                          if k.startswith("damage_")})
        if clock is not None:
            clock.restore_scalars({k.removeprefix("clock_"): float(v) for k, v in a.items() if k.startswith("clock_")})
    except KeyError as e:
        raise ConfigError(f"--restart: {path} lacks the value {e.args[0]} (written by another version of the "
                          "solver?); start the run again without --restart") from None
    if model.u_prev is not None:
        model.u_prev.x.scatter_forward()
    model.u.x.scatter_forward()
    if model.damage is not None:
        model.damage.zeta.x.scatter_forward()
    return Checkpoint(int(a["step"]), float(a["t"]), int(a["part"]) + 1)
