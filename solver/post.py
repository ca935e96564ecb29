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
    """Read a results directory through ``solution.xdmf``: node coordinates, cell connectivity,
    the written times, and {field: {t: values}} (P1 fields per node, DG0 fields per cell),
    all in the node and cell order of the first data part."""
    import xml.etree.ElementTree as ET

    import h5py

    directory = Path(directory)
    grids = ET.parse(directory / "solution.xdmf").getroot().find("Domain").find("Grid").findall("Grid")
    files: dict[str, h5py.File] = {}

    def load(item) -> np.ndarray:
        name, dataset = item.text.strip().split(":", 1)
        if name not in files:
            files[name] = h5py.File(directory / name, "r")
        return files[name][dataset][...]

    out: dict = {"fields": {}, "times": []}
    perms: dict[str, tuple[np.ndarray, np.ndarray]] = {}  # geometry dataset -> (node, cell) maps to the first
    try:
        for g in grids:
            t = float(g.find("Time").get("Value"))
            out["times"].append(t)
            gkey = g.find("Geometry").find("DataItem").text.strip()
            if gkey not in perms:
                x = load(g.find("Geometry").find("DataItem"))
                cells = load(g.find("Topology").find("DataItem"))
                if "geometry" not in out:
                    out["geometry"], out["topology"] = x, cells
                perms[gkey] = (_match(out["geometry"], x),
                               _match(out["geometry"][out["topology"]].mean(axis=1), x[cells].mean(axis=1)))
            node, cell = perms[gkey]
            for att in g.findall("Attribute"):
                values = load(att.find("DataItem"))
                values = values[node] if att.get("Center") == "Node" else values[cell]
                out["fields"].setdefault(att.get("Name"), {})[t] = values
    finally:
        for f in files.values():
            f.close()
    return out


def _match(reference: np.ndarray, points: np.ndarray) -> np.ndarray:
    """Index into ``points`` of each reference point (parts written by other partitions order them differently)."""
    def order(p):
        return np.lexsort(np.round(p, 10).T[::-1])

    ro, po = order(reference), order(points)
    index = np.empty(len(reference), dtype=np.int64)
    index[ro] = po
    if not np.allclose(points[index], reference, rtol=0, atol=1e-9):
        raise ValueError("a data part has a different mesh")
    return index


def read_csv(path: str | Path) -> list[dict[str, float]]:
    """Read a timeseries.csv back as a list of rows of floats."""
    with open(path, newline="") as fh:
        return [{k: float(v) for k, v in row.items()} for row in csv.DictReader(fh)]
