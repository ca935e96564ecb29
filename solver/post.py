"""Post-processing that reads what a run wrote (never the live solver objects), plus point probes."""

from __future__ import annotations

import csv
from pathlib import Path

import numpy as np


def point_value(f, point) -> np.ndarray:
    """Value of a dolfinx Function at a physical point, the same on every rank."""
    from dolfinx import geometry

    mesh = f.function_space.mesh
    comm = mesh.comm
    p = np.zeros((1, 3))
    p[0, : len(point)] = point
    tree = geometry.BoundingBoxTree(mesh, mesh.topology.dim)
    cells = geometry.compute_colliding_cells(mesh, geometry.compute_collisions(tree, p), p).links(0)
    val = f.eval(p, cells[:1]) if len(cells) else None
    found = [v for v in comm.allgather(val) if v is not None]
    if not found:
        raise ValueError(f"point {point} is outside the mesh")
    return found[0]


def read_results(directory: str | Path) -> dict:
    """Read solution.h5: node coordinates, cell connectivity, and {name: {t: values}} per time.

    P1 fields are per node (aligned with ``geometry``), DG0 fields per cell.
    """
    import h5py

    path = Path(directory) / "solution.h5"
    out: dict = {"fields": {}}
    with h5py.File(path, "r") as h5:
        mesh_name = next(iter(h5["Mesh"]))
        out["geometry"] = h5[f"Mesh/{mesh_name}/geometry"][...]
        out["topology"] = h5[f"Mesh/{mesh_name}/topology"][...]
        for name, group in h5["Function"].items():
            out["fields"][name] = {float(k.replace("_", ".")): group[k][...] for k in group}
    out["times"] = sorted(next(iter(out["fields"].values())).keys()) if out["fields"] else []
    return out


def read_csv(path: str | Path) -> list[dict[str, float]]:
    """Read a timeseries.csv back as a list of rows of floats."""
    with open(path, newline="") as fh:
        return [{k: float(v) for k, v in row.items()} for row in csv.DictReader(fh)]
