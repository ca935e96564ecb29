"""Writers: XDMF time series (ParaView), CSV time series (rank 0), resolved config.

XDMF cannot hold quadrature functions, so stresses are written as DG0 cell
averages (exact L2 projection onto piecewise constants).
"""

from __future__ import annotations

import os
from pathlib import Path

import numpy as np
import ufl
from dolfinx import fem, io
from dolfinx.fem import petsc as fpetsc
from mpi4py import MPI
from petsc4py import PETSc

CSV_COLUMNS = (
    "step", "t", "newton_iterations", "linear_solves", "factorizations", "residual", "contact_force",
    "contact_length", "max_penetration", "zeta_min", "zeta_max", "zeta_raw_min", "zeta_raw_max", "zeta_clipped",
    "strain_norm", "zeta_norm", "time_damage", "time_memory", "time_displacement", "time_diagnostics", "time_output",
    "wall_time",
)
TIMING_COLUMNS = ("time_damage", "time_memory", "time_displacement", "time_diagnostics", "time_output", "wall_time")


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


def von_mises_array(s: np.ndarray, dim: int, s33: np.ndarray | None = None) -> np.ndarray:
    """von Mises of an array of tensors (n, dim*dim): the paper's plane formula in 2-D; with the
    out-of-plane stresses ``s33`` (plane strain) the full one, sqrt(((a-b)^2 + (b-c)^2 + (c-a)^2)/2 + 3 t^2)."""
    s = s.reshape(-1, dim, dim)
    if dim == 2 and s33 is not None:
        a, b, c, t = s[:, 0, 0], s[:, 1, 1], s33, s[:, 0, 1]
        return np.sqrt(((a - b) ** 2 + (b - c) ** 2 + (c - a) ** 2) / 2 + 3 * t * t)
    if dim == 2:
        a, b, c = s[:, 0, 0], s[:, 1, 1], s[:, 0, 1]
        return np.sqrt(a * a + b * b - a * b + 3 * c * c)
    dev = s - np.trace(s, axis1=1, axis2=2)[:, None, None] * np.eye(3) / 3
    return np.sqrt(1.5 * np.einsum("nij,nij->n", dev, dev))


def flush_hdf5() -> None:
    """Flush every HDF5 file dolfinx has open (collective), so a killed run leaves readable data.

    dolfinx 0.5.2 keeps its HDF5 file open between writes and offers no flush; its library
    (libhdf5_openmpi, not h5py's) is reached through ctypes.
    """
    import ctypes

    try:
        lib = ctypes.CDLL("libhdf5_openmpi.so.103")
    except OSError:  # another build: nothing we can flush
        return
    lib.H5Fget_obj_count.restype = ctypes.c_ssize_t
    lib.H5Fget_obj_count.argtypes = [ctypes.c_int64, ctypes.c_uint]
    lib.H5Fget_obj_ids.restype = ctypes.c_ssize_t
    lib.H5Fget_obj_ids.argtypes = [ctypes.c_int64, ctypes.c_uint, ctypes.c_size_t, ctypes.POINTER(ctypes.c_int64)]
    lib.H5Fflush.argtypes = [ctypes.c_int64, ctypes.c_int]
    H5F_OBJ_FILE, H5F_OBJ_ALL, H5F_SCOPE_GLOBAL = 0x0001, 0x001F, 1
    n = lib.H5Fget_obj_count(H5F_OBJ_ALL, H5F_OBJ_FILE)
    if n <= 0:
        return
    ids = (ctypes.c_int64 * n)()
    lib.H5Fget_obj_ids(H5F_OBJ_ALL, H5F_OBJ_FILE, n, ids)
    for fid in ids:
        lib.H5Fflush(fid, H5F_SCOPE_GLOBAL)


class XDMFWriter:
    """``solution.xdmf``: one temporal collection over the data parts in ``fields/``.

    dolfinx writes the data of this run's part to ``fields/part{k}.h5`` (in parallel), with
    its own XML beside it, rewritten non-atomically and with one collection per function.
    After each written level the HDF5 file is flushed and rank 0 rewrites ``solution.xdmf``
    atomically, each time level one grid carrying every field: ParaView and meshio read it
    as one dataset, and a crash leaves it readable. A restart writes a new part and keeps
    the earlier levels (``prefix``) up to its checkpoint.
    """

    def __init__(self, directory: Path, mesh, functions: list[fem.Function], part: int = 0,
                 prefix: list | None = None) -> None:
        self.directory = Path(directory)
        self.comm = mesh.comm
        fields = self.directory / "fields"
        if self.comm.rank == 0:
            fields.mkdir(exist_ok=True)
        self.comm.barrier()
        self.part = fields / f"part{part}.xdmf"
        self.file = io.XDMFFile(mesh.comm, str(self.part), "w")
        self.file.write_mesh(mesh)
        self.functions = functions
        self.prefix = prefix or []

    def write(self, t: float) -> None:
        for f in self.functions:
            self.file.write_function(f, t)
        flush_hdf5()
        self.comm.barrier()
        if self.comm.rank == 0:
            write_merged_xdmf(self.directory, self.prefix + part_grids(self.part))

    def close(self) -> None:
        self.file.close()


def part_grids(part_xdmf: Path) -> list:
    """Grids (one per written time, every field as an attribute) of a dolfinx XDMF file,
    with data paths made relative to the results directory."""
    import xml.etree.ElementTree as ET

    domain = ET.parse(part_xdmf).getroot().find("Domain")
    grids = domain.findall("Grid")
    mesh_grid = next(g for g in grids if g.get("GridType") == "Uniform")
    by_time: dict[str, list] = {}
    for coll in (g for g in grids if g.get("GridType") == "Collection"):
        for g in coll.findall("Grid"):
            by_time.setdefault(g.find("Time").get("Value"), []).extend(g.findall("Attribute"))
    out = []
    for t in sorted(by_time, key=float):
        g = ET.Element("Grid", Name="solution", GridType="Uniform")
        g.append(mesh_grid.find("Topology"))
        g.append(mesh_grid.find("Geometry"))
        ET.SubElement(g, "Time", Value=t)
        g.extend(by_time[t])
        for item in g.iter("DataItem"):
            if not item.text.startswith("fields/"):
                item.text = f"fields/{item.text.strip()}"
        out.append(g)
    return out


def write_merged_xdmf(directory: Path, grids: list) -> None:
    """Write ``solution.xdmf`` (one temporal collection) atomically."""
    import copy
    import xml.etree.ElementTree as ET

    root = ET.Element("Xdmf", Version="3.0")
    coll = ET.SubElement(ET.SubElement(root, "Domain"), "Grid", Name="solution", GridType="Collection",
                         CollectionType="Temporal")
    coll.extend(copy.deepcopy(grids))
    tree = ET.ElementTree(root)
    ET.indent(tree, space="  ")
    path = Path(directory) / "solution.xdmf"
    tmp = path.with_name(path.name + ".tmp")
    with open(tmp, "wb") as fh:
        fh.write(b'<?xml version="1.0"?>\n<!DOCTYPE Xdmf SYSTEM "Xdmf.dtd" []>\n')
        tree.write(fh, encoding="utf-8", xml_declaration=False)
    os.replace(tmp, path)


def merged_grids(directory: Path, until: float | None = None) -> list:
    """The grids of an existing ``solution.xdmf`` (times <= until)."""
    import xml.etree.ElementTree as ET

    coll = ET.parse(Path(directory) / "solution.xdmf").getroot().find("Domain").find("Grid")
    grids = coll.findall("Grid")
    if until is None:
        return grids
    return [g for g in grids if float(g.find("Time").get("Value")) <= until * (1 + 1e-12) + 1e-300]


class CSVWriter:
    """Rows of the time series, written by rank 0, each row one ``write()`` of a whole line.

    ``columns``: CSV_COLUMNS and the scene's own (the reactions of its Dirichlet parts).

    The file is opened in append mode and every row goes out in a single system call, so
    a killed run leaves only complete rows. ``keep`` lines (a restart's rows up to its
    checkpoint, as written) are rewritten first, atomically.
    """

    def __init__(self, path: Path, comm: MPI.Comm, keep: list[str] | None = None,
                 columns: tuple[str, ...] = CSV_COLUMNS) -> None:
        self.comm = comm
        self.fd = None
        self.columns = columns
        if comm.rank == 0:
            text = ",".join(columns) + "\n" + "".join(keep or [])
            write_text_atomic(path, text)
            self.fd = os.open(path, os.O_WRONLY | os.O_APPEND)

    def write(self, row: dict) -> None:
        if self.fd is not None:
            os.write(self.fd, _line(row, self.columns).encode())

    def close(self) -> None:
        if self.fd is not None:
            os.close(self.fd)
            self.fd = None


def _line(row: dict, columns: tuple[str, ...] = CSV_COLUMNS) -> str:
    return ",".join(_fmt(row[k]) for k in columns) + "\n"


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

