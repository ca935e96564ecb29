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
    """One XDMF file, mesh written once, functions appended per written level."""

    def __init__(self, path: Path, mesh, functions: list[fem.Function]) -> None:
        self.file = io.XDMFFile(mesh.comm, str(path), "w")
        self.file.write_mesh(mesh)
        self.functions = functions

    def write(self, t: float) -> None:
        for f in self.functions:
            self.file.write_function(f, t)

    def close(self) -> None:
        self.file.close()


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


def read_csv(path: str | Path) -> list[dict[str, float]]:
    """Read a timeseries.csv back as a list of rows of floats."""
    with open(path, newline="") as fh:
        return [{k: float(v) for k, v in row.items()} for row in csv.DictReader(fh)]
