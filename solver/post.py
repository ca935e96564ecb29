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
    """Read a results directory through ``solution.xdmf``: node coordinates (``geometry``), cells
    (``topology``), the written ``times``, and ``fields`` {field: {t: values}} (P1 fields per node,
    DG0 fields per cell; tensors as XX, YY, ZZ, XY, YZ, XZ). Rows are in the mesh's input order,
    the same whatever the number of ranks that wrote them (solver/xdmf.py)."""
    from .xdmf import read_series

    res = read_series(Path(directory) / "solution.xdmf")
    out = {"geometry": res["points"], "topology": res["cells"], "times": res["times"], "fields": {}}
    for name, values in res["fields"].items():
        out["fields"][name] = {t: v for t, v in zip(res["times"], values) if v is not None}
    return out


def read_csv(path: str | Path) -> list[dict[str, float]]:
    """Read a timeseries.csv back as a list of rows of floats."""
    with open(path, newline="") as fh:
        return [{k: float(v) for k, v in row.items()} for row in csv.DictReader(fh)]
