"""Writers: XDMF time series (ParaView), CSV time series (rank 0), resolved config.

XDMF cannot hold quadrature functions, so stresses are written as DG0 cell
averages (exact L2 projection onto piecewise constants).
"""

from __future__ import annotations

import csv
import os
from pathlib import Path

import numpy as np
import ufl
from dolfinx import fem, io
from dolfinx.fem import petsc as fpetsc
from mpi4py import MPI
from petsc4py import PETSc

CSV_COLUMNS = (
    "step", "t", "newton_iterations", "factorizations", "residual", "contact_force", "contact_length",
    "zeta_min", "zeta_max", "zeta_clipped", "strain_norm", "zeta_norm",
    "time_damage", "time_memory", "time_displacement", "time_output", "wall_time",
)
TIMING_COLUMNS = ("time_damage", "time_memory", "time_displacement", "time_output", "wall_time")


class CellAverage:
    """Cell averages of a UFL expression into a DG0 function: the L2 projection onto DG0."""

    def __init__(self, expr, target: fem.Function, dx: ufl.Measure) -> None:
        self.target = target
        V = target.function_space
        tau = ufl.TestFunction(V)
        self.form = fem.form(ufl.inner(expr, tau) * dx)
        self.vec = fpetsc.create_vector(self.form)
        mesh = V.mesh
        S = fem.FunctionSpace(mesh, ("DG", 0))
        vol = fpetsc.assemble_vector(fem.form(ufl.TestFunction(S) * ufl.dx))
        vol.ghostUpdate(addv=PETSc.InsertMode.ADD, mode=PETSc.ScatterMode.REVERSE)
        self.bs = V.dofmap.index_map_bs
        n = V.dofmap.index_map.size_local
        self.inv_vol = 1.0 / vol.array_r[:n]
        self.n = n

    def update(self) -> None:
        with self.vec.localForm() as v:
            v.set(0.0)
        fpetsc.assemble_vector(self.vec, self.form)
        self.vec.ghostUpdate(addv=PETSc.InsertMode.ADD, mode=PETSc.ScatterMode.REVERSE)
        vals = self.target.x.array[: self.n * self.bs].reshape(self.n, self.bs)
        vals[:] = self.vec.array_r.reshape(self.n, self.bs) * self.inv_vol[:, None]
        self.target.x.scatter_forward()


def von_mises_array(s: np.ndarray, dim: int) -> np.ndarray:
    """von Mises of an array of tensors (n, dim*dim): the paper's plane formula in 2-D."""
    s = s.reshape(-1, dim, dim)
    if dim == 2:
        a, b, c = s[:, 0, 0], s[:, 1, 1], s[:, 0, 1]
        return np.sqrt(a * a + b * b - a * b + 3 * c * c)
    dev = s - np.trace(s, axis1=1, axis2=2)[:, None, None] * np.eye(3) / 3
    return np.sqrt(1.5 * np.einsum("nij,nij->n", dev, dev))


class XDMFWriter:
    """XDMF time series: dolfinx writes the data (HDF5, in parallel); the XML is then regrouped.

    dolfinx 0.5.2 puts every function in its own temporal collection, which ParaView
    loads as separate blocks and meshio not at all. After each written level rank 0
    rewrites the XML (atomically) as one temporal collection whose grids carry every
    field, so Warp By Vector and colouring by a cell field work on one dataset.
    """

    def __init__(self, path: Path, mesh, functions: list[fem.Function]) -> None:
        self.path = Path(path)
        self.comm = mesh.comm
        self.file = io.XDMFFile(mesh.comm, str(path), "w")
        self.file.write_mesh(mesh)
        self.functions = functions

    def write(self, t: float) -> None:
        for f in self.functions:
            self.file.write_function(f, t)
        self.comm.barrier()
        if self.comm.rank == 0:
            merge_xdmf(self.path)

    def close(self) -> None:
        self.file.close()
        self.comm.barrier()
        if self.comm.rank == 0:
            merge_xdmf(self.path)


def merge_xdmf(path: Path) -> None:
    """Regroup dolfinx's per-function collections into one temporal collection (idempotent)."""
    import xml.etree.ElementTree as ET

    tree = ET.parse(path)
    domain = tree.getroot().find("Domain")
    grids = domain.findall("Grid")
    if [g.get("Name") for g in grids] == ["solution"]:
        return  # already merged (dolfinx did not rewrite since)
    mesh_grid = next(g for g in grids if g.get("GridType") == "Uniform")
    collections = [g for g in grids if g.get("GridType") == "Collection"]
    topology, geometry = mesh_grid.find("Topology"), mesh_grid.find("Geometry")
    by_time: dict[str, list] = {}
    for coll in collections:
        for g in coll.findall("Grid"):
            by_time.setdefault(g.find("Time").get("Value"), []).extend(g.findall("Attribute"))
    for g in grids:
        domain.remove(g)
    out = ET.SubElement(domain, "Grid", Name="solution", GridType="Collection", CollectionType="Temporal")
    for t in sorted(by_time, key=float):
        g = ET.SubElement(out, "Grid", Name="solution", GridType="Uniform")
        g.append(topology)
        g.append(geometry)
        ET.SubElement(g, "Time", Value=t)
        g.extend(by_time[t])
    ET.indent(tree, space="  ")
    tmp = path.with_name(path.name + ".tmp")
    with open(tmp, "wb") as fh:
        fh.write(b'<?xml version="1.0"?>\n<!DOCTYPE Xdmf SYSTEM "Xdmf.dtd" []>\n')
        tree.write(fh, encoding="utf-8", xml_declaration=False)
    os.replace(tmp, path)


class CSVWriter:
    """Rows of the time series, written and flushed by rank 0 only."""

    def __init__(self, path: Path, comm: MPI.Comm) -> None:
        self.comm = comm
        self.fh = None
        if comm.rank == 0:
            self.fh = open(path, "w", newline="")
            self.writer = csv.DictWriter(self.fh, fieldnames=CSV_COLUMNS)
            self.writer.writeheader()
            self.fh.flush()

    def write(self, row: dict) -> None:
        if self.fh is not None:
            self.writer.writerow({k: _fmt(row[k]) for k in CSV_COLUMNS})
            self.fh.flush()

    def close(self) -> None:
        if self.fh is not None:
            self.fh.close()


def _fmt(v) -> str:
    if isinstance(v, float):
        return repr(v)
    return str(v)


def write_text_atomic(path: Path, text: str) -> None:
    """Write a small file through a temporary name and a rename."""
    tmp = path.with_name(path.name + ".tmp")
    with open(tmp, "w") as fh:
        fh.write(text)
        fh.flush()
        os.fsync(fh.fileno())
    os.replace(tmp, path)

