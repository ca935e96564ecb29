"""XDMF time series written with h5py, that a SIGKILL at any moment cannot damage.

Layout of a results directory (``name`` = ``solution``)::

    solution.xdmf              one temporal collection; each listed level is one <Grid> with every field
    fields/mesh.h5             /geometry, /topology: written once
    fields/levels_000000.h5    /0000/<field>, /0001/<field>, ...: levels 0, 1, ... of the series
    fields/levels_000100.h5    /0000/<field> is level 100, ... (a chunk holds up to 100 levels, 64 MiB)

Another series in the same directory (``name`` = ``contact``: Γ_C's facet mesh, :mod:`solver.io.contact_series`)
prefixes its files with its name: ``fields/contact_mesh.h5``, ``fields/contact_levels_000000.h5``, ...

A chunk file is named after the index of its first level in the series and holds one group per
level (``NNNN`` = index - first) with one dataset per field, ``(rows,)`` or ``(rows, components)``.
A chunk may hold fewer levels: it is also closed at every checkpoint (see *Crash safety*).

**Order.** Nodes and cells are written in the mesh's input order (``input_global_indices``,
``original_cell_index``), gathered to rank 0. The files therefore do not depend on the
partition: one process and ``mpirun -n N`` write the same rows, and a restart on another
number of ranks continues the same series on the same mesh file.

**Why a file per chunk of levels, a dataset per level and field.** The XML then names each
level's data by a plain path (``fields/levels_000100.h5:/0003/damage``), which every XDMF
reader understands; one resizable dataset per field would need ``HyperSlab`` items, which
meshio's reader does not read. A file per level would make thousands of files, and meshio
keeps each one open (past the usual limit of 1024 descriptors).

**Crash safety (process death: SIGKILL, OOM killer, a cancelled job).** The XML lists only
levels of chunk files that were written completely and will not be written again.
- *Data.* The chunk being filled is a plain file on rank 0, written level by level at the offsets its HDF5
  template gives (see *Cost*); it is closed when it holds ``MAX_LEVELS_PER_CHUNK`` levels or ``CHUNK_BYTES``, at
  every :meth:`XDMFSeries.flush` (the stepper calls it before each checkpoint) and at :meth:`XDMFSeries.close`
  (a chunk closed before it is full is written again as the file of its levels only, beside it, and renamed over
  it; a run says how many levels it writes up to its next checkpoint or its end, ``write(..., left)``, and a chunk
  opened then holds no more, so that it is full when closed and written once), and only after that are its levels
  listed. A kill before leaves at most an unlisted file. No HDF5 file is
  ever open for writing on disk, and a listed file is only ever read.
- *XML.* ``solution.xdmf`` is never modified in place: the whole file is written to
  ``.solution.xdmf.tmp`` in the same directory and renamed over it (``os.replace``,
  atomic on POSIX). A reader, or the file left by a kill, sees the old list or the new one.
- *Restart.* ``XDMFSeries(..., keep_until=t)`` removes what a kill may leave (an unlisted
  chunk file, the temporary XML), keeps the listed levels with time <= t, checks that
  ``fields/mesh.h5`` is this mesh and appends after them in a new chunk file.
The price: after a kill, the levels written since the last chunk was closed are not listed
(up to 100 levels, at most those since the last checkpoint). A restart recomputes them from the checkpoint anyway, because ``flush()``
lists every level before the checkpoint is written. Writes are not ``fsync``ed for safety:
they survive the death of the process, not of the machine.

**Cost.** The groups and datasets of a chunk are made by HDF5 once per series and chunk size
(:class:`_Template`: contiguous datasets allocated at creation, whose data offsets in the file are then known);
a level's values are written into the chunk's file at those offsets, with no HDF5 call (a dataset made per level
and field cost some 50 us, most of the writer's time). A level's part of the file (its data and the HDF5 metadata
around it; several levels' where HDF5 put their small datasets in one block) of up to ``STAGE_BYTES`` is assembled
in memory and written with one call; a larger one is written field by field, so that the writer holds one field of
the level beside the solver's state, never a chunk. The XML is rewritten once per closed chunk, so its cost per
level is the file's size over the levels per chunk: O(listed levels / 100). Levels are written in the calling
thread. (Figures: docs/developer/design-notes.md, docs/benchmarks/speed.md.) One thread settles each closed chunk
(``fdatasync``, then its pages dropped from the page cache; both release the GIL), so that the kernel does not write
GBs of dirty pages back late in a long run, where that slows the memory-bound solves (``SETTLE_CHUNKS``).

**Failures.** A write that fails (a full disk: ENOSPC) raises :class:`SeriesError` with one
line and the time ``t`` of the failed level (for a chunk's file or the XML: of the chunk's
last level). The complete levels of the open chunk are listed if they can still be written,
a chunk file that could not be listed is removed, and the series takes no more levels.

This module needs numpy, h5py and mpi4py; dolfinx only for :func:`dolfinx_layout`.
"""

from __future__ import annotations

import bisect
import dataclasses
import os
import queue
import re
import tempfile
import threading
import xml.etree.ElementTree as ET
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path

import h5py
import numpy as np

from solver.errors import ResultsError

PRECISIONS = {"double": np.dtype("<f8"), "single": np.dtype("<f4")}
KINDS = {"Scalar": 1, "Vector": 3, "Tensor6": 6}  # components in the file
CENTERS = ("Node", "Cell")
CELL_TYPES = {("triangle", 3): "Triangle", ("tetrahedron", 4): "Tetrahedron"}
FACET_TYPES = {2: "Polyline", 3: "Triangle"}  # a boundary's facets (contact.xdmf): segments in 2-D, triangles in 3-D
MAX_LEVELS_PER_CHUNK = 100
CHUNK_BYTES = 64 * 2**20  # the largest chunk file
SETTLE_CHUNKS = True  # fdatasync each closed chunk and drop its pages, in a thread (see _Settler)

_HEAD = ('<?xml version="1.0"?>\n<!DOCTYPE Xdmf SYSTEM "Xdmf.dtd" []>\n<Xdmf Version="3.0">\n  <Domain>\n'
         '    <Grid Name="{name}" GridType="Collection" CollectionType="Temporal">\n')
_TAIL = "    </Grid>\n  </Domain>\n</Xdmf>\n"


class SeriesError(RuntimeError):
    """Writing or continuing the series failed; the message is one line for the user.

    ``t`` is the time of the level whose write failed (None: not a level's write)."""

    def __init__(self, message: str, t: float | None = None) -> None:
        super().__init__(message)
        self.t = t


@dataclass(frozen=True)
class FieldSpec:
    """One written field: its name, where it lives (``Node``/``Cell``) and its XDMF attribute type.

    ``Vector`` is written with 3 components (ParaView warps by 3-vectors) and ``Tensor6``
    with the 6 of a symmetric tensor in ParaView's order XX, YY, ZZ, XY, YZ, XZ.
    """

    name: str
    center: str
    kind: str

    def __post_init__(self) -> None:
        if not re.fullmatch(r"[A-Za-z_][A-Za-z0-9_]*", self.name):
            raise ValueError(f"field name {self.name!r}: letters, digits and _ only")
        if self.center not in CENTERS:
            raise ValueError(f"field {self.name}: center {self.center!r} is not one of {CENTERS}")
        if self.kind not in KINDS:
            raise ValueError(f"field {self.name}: kind {self.kind!r} is not one of {tuple(KINDS)}")

    @property
    def ncomp(self) -> int:
        return KINDS[self.kind]


@dataclass
class Layout:
    """This rank's owned nodes and cells, and where they go in the file.

    ``node_keys``/``cell_keys`` are global, partition-independent keys of the owned rows
    (the mesh's input indices); the file holds rows in increasing key order. ``cells``
    gives each owned cell's nodes as keys too.
    """

    comm: object
    points: np.ndarray | None  # (owned nodes, gdim); None in a series' copy once it wrote the mesh
    node_keys: np.ndarray  # (owned nodes,)
    cells: np.ndarray | None  # (owned cells, nodes per cell), node keys; None as points
    cell_keys: np.ndarray  # (owned cells,)
    cell_type: str  # XDMF TopologyType
    counts: dict[str, int] = field(default_factory=dict)  # filled by XDMFSeries: global rows per center

    @property
    def local(self) -> dict[str, int]:
        return {"Node": len(self.node_keys), "Cell": len(self.cell_keys)}


def dolfinx_layout(mesh) -> Layout:
    """The :class:`Layout` of a dolfinx (0.5) P1 mesh: owned geometry nodes and owned cells, keyed by input index."""
    geo, top = mesh.geometry, mesh.topology
    tdim = top.dim
    n_nodes = geo.index_map().size_local
    n_cells = top.index_map(tdim).size_local
    x_dofs = _cell_nodes(mesh)
    keys = np.asarray(geo.input_global_indices, dtype=np.int64)
    name = (top.cell_name(), x_dofs.shape[1])
    if name not in CELL_TYPES:
        raise ValueError(f"XDMF writer: cells {name[0]} with {name[1]} nodes are not supported (P1 simplices only)")
    return Layout(comm=mesh.comm, points=np.asarray(geo.x[:n_nodes, : geo.dim]), node_keys=keys[:n_nodes],
                  cells=keys[x_dofs[:n_cells]], cell_keys=np.asarray(top.original_cell_index[:n_cells], dtype=np.int64),
                  cell_type=CELL_TYPES[name])


def _cell_nodes(mesh) -> np.ndarray:
    """Geometry nodes of every local cell (owned, then ghosts), one row per cell."""
    imap = mesh.topology.index_map(mesh.topology.dim)
    n = imap.size_local + imap.num_ghosts
    return mesh.geometry.dofmap.array.reshape(n, -1) if n else np.zeros((0, mesh.topology.dim + 1), np.int32)


class DolfinxRows:
    """Owned rows of dolfinx Functions in a :func:`dolfinx_layout` order: P1 at the geometry nodes, DG0 per cell."""

    def __init__(self, mesh) -> None:
        self.mesh = mesh
        geo, top = mesh.geometry, mesh.topology
        self.n_nodes = geo.index_map().size_local
        self.n_cells = top.index_map(top.dim).size_local
        self._x_dofs = _cell_nodes(mesh)
        self._maps: dict[int, tuple[object, RowMap]] = {}

    def _map(self, V) -> RowMap:
        key = id(V)
        if key not in self._maps or self._maps[key][0] is not V:
            cell_dofs = V.dofmap.list.array.reshape(self._x_dofs.shape[0], -1)
            family, degree = V.ufl_element().family(), V.ufl_element().degree()
            if degree == 0:  # DG0: one dof per cell
                self._maps[key] = (V, RowMap(cell_dofs[: self.n_cells, 0], V.dofmap.index_map_bs))
            elif degree == 1 and family in ("Lagrange", "Q", "P", "CG") and cell_dofs.shape[1] == self._x_dofs.shape[1]:
                node_to_dof = np.empty(self._x_dofs.max(initial=-1) + 1, dtype=np.int64)
                node_to_dof[self._x_dofs.ravel()] = cell_dofs.ravel()  # P1 and the geometry share the cell-local order
                self._maps[key] = (V, RowMap(node_to_dof[: self.n_nodes], V.dofmap.index_map_bs))
            else:
                raise ValueError(f"XDMF writer: {family} degree {degree} is not supported (P1 or DG0)")
        return self._maps[key][1]

    def dofs(self, V) -> np.ndarray:
        """The dof (block) of a scalar P1 or DG0 space at each owned node or cell."""
        m = self._map(V)
        return np.arange(m.n) if m.index is None else m.index[:: m.width] // m.width

    def entries(self, V) -> np.ndarray:
        """Where each owned node's (P1) or cell's (DG0) values lie in a function of ``V``'s ``x.array``: (rows, block)."""
        m = self._map(V)
        return (np.arange(m.n * m.width) if m.index is None else m.index).reshape(m.n, m.width)

    def rows(self, f) -> np.ndarray:
        """Values of ``f`` at this rank's owned nodes (P1) or cells (DG0), one row per node/cell."""
        return self._map(f.function_space).take(f.x.array)


class RowMap:
    """Takes given rows of a flat array of ``width``-wide rows, fast (numpy 1.24's 2-D fancy indexing costs
    about 10x a flat ``take``); the first rows in order are returned as a view."""

    def __init__(self, rows: np.ndarray, width: int) -> None:
        rows = np.asarray(rows, dtype=np.intp).ravel()
        self.n, self.width = len(rows), width
        identity = np.array_equal(rows, np.arange(len(rows)))
        self.index = None if identity else (rows[:, None] * width + np.arange(width)).ravel()

    def take(self, values: np.ndarray) -> np.ndarray:
        if self.index is None:
            return values[: self.n * self.width].reshape(self.n, self.width)
        return np.take(values, self.index).reshape(self.n, self.width)


def vector3(rows: np.ndarray) -> np.ndarray:
    """Rows of 1-3 components padded with zeros to 3 (what ParaView's Warp By Vector needs)."""
    rows = rows.reshape(len(rows), -1) if rows.size else rows.reshape(0, rows.shape[-1] if rows.ndim == 2 else 1)
    if rows.shape[1] == 3:
        return rows
    out = np.zeros((len(rows), 3), dtype=rows.dtype)
    out[:, : rows.shape[1]] = rows
    return out


class Vector3:
    """:func:`vector3` into an array kept between calls (a writer's level after level): its zero columns are written
    once, and a level copies the 1-2 components in, without a new (rows, 3) array each time. The result is valid
    until the next call (:meth:`XDMFSeries.write` is done with its values when it returns)."""

    def __init__(self) -> None:
        self._out: np.ndarray | None = None
        self._width = 0

    def __call__(self, rows: np.ndarray) -> np.ndarray:
        rows = rows.reshape(len(rows), -1) if rows.size else rows.reshape(0, rows.shape[-1] if rows.ndim == 2 else 1)
        if rows.shape[1] == 3:
            return rows
        out = self._out
        if out is None or out.shape[0] != len(rows) or out.dtype != rows.dtype or self._width != rows.shape[1]:
            out = self._out = np.zeros((len(rows), 3), dtype=rows.dtype)
            self._width = rows.shape[1]
        out[:, : rows.shape[1]] = rows
        return out


def tensor6(rows: np.ndarray, dim: int, zz: np.ndarray | None = None) -> np.ndarray:
    """Symmetric tensors (rows of dim*dim, row-major) as XX, YY, ZZ, XY, YZ, XZ (ParaView's order; 2-D: YZ, XZ = 0,
    and ZZ = ``zz`` where given (plane strain's sigma_33), else 0).

    The symmetric part is written: (T + T^T)/2, which is T for the stresses written here.
    """
    t = rows.reshape(len(rows), dim, dim)
    out = np.zeros((len(rows), 6), dtype=rows.dtype)
    out[:, 0], out[:, 1], out[:, 3] = t[:, 0, 0], t[:, 1, 1], 0.5 * (t[:, 0, 1] + t[:, 1, 0])
    if dim == 2 and zz is not None:
        out[:, 2] = zz
    if dim == 3:
        out[:, 2] = t[:, 2, 2]
        out[:, 4] = 0.5 * (t[:, 1, 2] + t[:, 2, 1])
        out[:, 5] = 0.5 * (t[:, 0, 2] + t[:, 2, 0])
    return out


# ---------------------------------------------------------------------------- files
# The three functions below are the only places that write series files; tests wrap them to
# inject a kill or a full disk (tests/faults.py).


def _write_dataset(chunk: _Chunk, slot: int, name: str, values: np.ndarray, rows: np.ndarray) -> None:
    """One field of one level: ``values[rows]`` (the field in file order) written where its dataset's data lies in
    the chunk's file (through the level's staging buffer when the level is small)."""
    chunk.put(slot, name, values, rows)


def _write_file(path: Path, data: bytes) -> None:
    """Write ``data`` as the whole of a new file ``path`` (a failure names the file)."""
    try:
        with open(path, "wb") as fh:
            fh.write(data)
    except OSError as exc:
        raise OSError(exc.errno, exc.strerror, str(path)) from None


def _close_chunk(chunk: _Chunk) -> None:
    """Complete a chunk's file: a full chunk's is complete once its last level is written; one closed early is
    written again as the file of its levels only."""
    chunk.finish()


def _remove(path: Path) -> None:
    try:
        path.unlink(missing_ok=True)
    except OSError:
        pass


def _replace_file(path: Path, tmp: Path, data: bytes) -> None:
    """Make ``data`` the content of ``path`` atomically: written to ``tmp`` (same directory), then renamed."""
    try:
        _write_file(tmp, data)
        os.replace(tmp, path)
    except BaseException:
        _remove(tmp)
        raise


def _pwrite(fd: int, data, offset: int, path: Path) -> None:
    """All of ``data`` (bytes or a contiguous array) at ``offset`` of the open file ``fd`` (a failure names the file)."""
    view = memoryview(data).cast("B")
    try:
        while len(view):
            done = os.pwrite(fd, view, offset)
            view, offset = view[done:], offset + done
    except OSError as exc:
        raise OSError(exc.errno, exc.strerror, str(path)) from None


ABOUT = "solver.xdmf chunk: group NNNN holds level FIRST + NNNN of the series (FIRST: the number in the file name)"
STAGE_BYTES = 4 * 2**20  # a level's part of a chunk file up to this size is assembled in memory and written at once


class _FileBytes:
    """The bytes of an open file, sliced like ``bytes`` (``len`` and ``[a:b]``), read where asked."""

    def __init__(self, fd: int) -> None:
        self.fd, self.size = fd, os.fstat(fd).st_size

    def __len__(self) -> int:
        return self.size

    def __getitem__(self, item: slice) -> bytes:
        start, stop, _ = item.indices(self.size)
        return os.pread(self.fd, max(0, stop - start), start)


class _Template:
    """The HDF5 file of a chunk of ``slots`` levels, made once: its bytes other than the datasets' data, and where
    each dataset's data lies (contiguous, allocated at creation).

    Every chunk of a series has the same groups and datasets, so a chunk's file is these bytes with its levels'
    values written at those offsets instead of an HDF5 group and datasets made per level: the HDF5 calls (some
    50 us per dataset) are paid once per series and chunk size, not per level and field. The file is cut into parts,
    ``[cut[p], cut[p + 1])``, each holding a slot's data and the HDF5 metadata around it (several slots' where HDF5
    put their small datasets in one block), so that the file is written part by part as its levels come and is
    complete with its last level. Only the metadata is kept in memory, not an image of the file."""

    def __init__(self, fields: Sequence[FieldSpec], counts: Mapping[str, int], dtype: np.dtype, slots: int) -> None:
        with tempfile.TemporaryDirectory(prefix="xdmf-template-") as tmp:  # a file whose data is never written: its
            path = Path(tmp) / "chunk.h5"  # metadata on disk, some kB (an HDF5 file in memory held the data's room)
            h5 = h5py.File(path, "w")
            try:
                h5.attrs["about"] = ABOUT
                dcpl = h5py.h5p.create(h5py.h5p.DATASET_CREATE)
                dcpl.set_obj_track_times(False)  # the same bytes from the same values
                dcpl.set_layout(h5py.h5d.CONTIGUOUS)
                dcpl.set_alloc_time(h5py.h5d.ALLOC_TIME_EARLY)  # the data's place known before it is written
                dcpl.set_fill_time(h5py.h5d.FILL_TIME_NEVER)  # every value is written
                tid = h5py.h5t.py_create(dtype)
                self.where: list[dict[str, tuple[int, int]]] = []  # per slot: field -> (offset, values)
                for slot in range(slots):
                    group = h5py.h5g.create(h5.id, f"{slot:04d}".encode())
                    where = {}
                    for f in fields:
                        n = counts[f.center]
                        shape = (n,) if f.ncomp == 1 else (n, f.ncomp)
                        ds = h5py.h5d.create(group, f.name.encode(), tid, h5py.h5s.create_simple(shape), dcpl=dcpl)
                        where[f.name] = (ds.get_offset() or 0, n * f.ncomp)  # no offset: no values (0 rows)
                    self.where.append(where)
            finally:
                h5.close()
            fd = os.open(path, os.O_RDONLY)
            try:
                self._layout(_FileBytes(fd), dtype, slots)
            finally:
                os.close(fd)

    def _layout(self, image: _FileBytes, dtype: np.dtype, slots: int) -> None:
        """The parts of the file and the metadata in each, from the template's file."""
        self.dtype, self.size, self.slots = dtype, len(image), slots
        spans = [[(o, o + c * dtype.itemsize) for o, c in where.values() if c] for where in self.where]
        # the file is cut before slot s where every earlier slot's data ends and every later slot's begins (HDF5 puts
        # small datasets of several slots in one block: those slots share a part)
        ends = np.maximum.accumulate([max((b for _, b in sp), default=0) for sp in spans])
        starts = np.minimum.accumulate([min((a for a, _ in sp), default=self.size) for sp in spans][::-1])[::-1]
        firsts = [0] + [s for s in range(1, slots) if ends[s - 1] <= starts[s]]
        self.cut = [0] + [int(starts[s]) for s in firsts[1:]] + [self.size]  # part p: [cut[p], cut[p + 1])
        self.part_of = np.repeat(np.arange(len(firsts)), np.diff(firsts + [slots])).tolist()  # slot -> its part
        self.last = [f - 1 for f in firsts[1:]] + [slots - 1]  # part -> its last slot
        head, at = [], 0  # the metadata (HDF5's own bytes): what lies between the datasets' values, cut at the parts
        for offset, end in sorted(v for span in spans for v in span) + [(self.size, self.size)]:
            while offset > at:
                stop = min(offset, next(c for c in self.cut if c > at))
                head.append((at, image[at:stop]))
                at = stop
            at = max(at, end)
        self.meta: list[list[tuple[int, bytes]]] = [[] for _ in firsts]  # per part: the metadata in it
        for offset, part in head:
            self.meta[min(bisect.bisect_right(self.cut, offset) - 1, len(firsts) - 1)].append((offset, part))
        sizes = [b - a for a, b in zip(self.cut, self.cut[1:]) if b - a <= STAGE_BYTES]
        self._stage = bytearray(max(sizes, default=0))  # the part being assembled (parts of up to STAGE_BYTES)
        self.views: list[dict[str, np.ndarray] | None] = [  # per slot of such a part: its fields' values in _stage
            {name: np.frombuffer(self._stage, dtype=dtype, count=count, offset=offset - self.cut[self.part_of[slot]])
             if count else np.zeros(0, dtype) for name, (offset, count) in where.items()}
            if self.cut[self.part_of[slot] + 1] - self.cut[self.part_of[slot]] <= STAGE_BYTES else None
            for slot, where in enumerate(self.where)]

    def stage(self, part: int) -> memoryview | None:
        """The buffer of part ``part`` of the file with its metadata in place (its values to be filled in
        :attr:`views`), when it is at most ``STAGE_BYTES``; None (a large part: written to the file piece by piece)."""
        start, end = self.cut[part], self.cut[part + 1]
        if end - start > STAGE_BYTES:
            return None
        buf = memoryview(self._stage)[: end - start]
        for offset, data in self.meta[part]:
            buf[offset - start: offset - start + len(data)] = data
        return buf


class _Chunk:
    """A chunk being filled (rank 0): its HDF5 file, written a level at a time and listed once it is closed.

    The file is a plain file written at the offsets its :class:`_Template` gives (never opened by HDF5 for writing);
    until its levels are listed, a kill leaves it unlisted, and a restart or the next run removes it. A level of up
    to ``STAGE_BYTES`` is assembled in memory and written with one call; a larger one is written field by field, so
    that the writer holds one field beside the solver's state. ``template(n)`` gives the :class:`_Template` of n
    slots: a chunk closed before it is full is written again as the file of its levels only (``finish``).
    """

    def __init__(self, path: Path, first: int, slots: int, template) -> None:
        self.path, self.first, self.slots, self.template = path, first, slots, template
        self.plan = template(slots)  # the template of its slots
        self.grids: list[str] = []  # the XML of its complete levels, listed once the file is closed
        self.times: list[float] = []
        self.fd: int | None = None
        try:
            self.fd = os.open(path, os.O_RDWR | os.O_CREAT | os.O_TRUNC, 0o644)
        except OSError as exc:
            raise OSError(exc.errno, exc.strerror, str(path)) from None
        self._buf: memoryview | None = None  # the part being assembled in memory (small parts), and its index
        self._part = -1

    @property
    def full(self) -> bool:
        return len(self.grids) >= self.slots

    def put(self, slot: int, name: str, values: np.ndarray, rows: np.ndarray) -> None:
        """A field at a slot: ``values[rows]``, taken straight into its part's buffer (one copy), or into an array
        written at once (a large part)."""
        if self._buf is not None:
            values.take(rows, out=self.plan.views[slot][name], mode="clip")  # the method: no dispatch of np.take
            return
        offset, count = self.plan.where[slot][name]
        if count:
            _pwrite(self.fd, np.take(values, rows), offset, self.path)

    def add(self, t: float, values: np.ndarray | list[np.ndarray], rows: Mapping[str, np.ndarray], grid_format: str) -> None:
        """Write one level into group ``NNNN``: each field ``values[rows[field]]`` (``values`` a list: the fields' own
        arrays, in the order of ``rows``); its grid is kept once every field is written."""
        slot = len(self.grids)
        full = self.plan
        part = full.part_of[slot]
        if slot == 0 or full.part_of[slot - 1] != part:  # the part's first level
            self._buf, self._part = full.stage(part), part
            if self._buf is None:  # a large part: its metadata now, then each field as it comes
                for offset, data in full.meta[part]:
                    _pwrite(self.fd, data, offset, self.path)
        if isinstance(values, list):
            for value, (name, index) in zip(values, rows.items()):
                _write_dataset(self, slot, name, value, index)
        else:
            for name, index in rows.items():
                _write_dataset(self, slot, name, values, index)
        if slot == full.last[part]:
            self._write_staged()
        self.grids.append(grid_format.format(t=repr(float(t)), file=f"fields/{self.path.name}", slot=f"{slot:04d}"))
        self.times.append(t)

    def _write_staged(self) -> None:
        """Write the part being assembled in memory (if any) to the file."""
        if self._buf is not None:
            buf, self._buf = self._buf, None
            _pwrite(self.fd, buf, self.plan.cut[self._part], self.path)

    def finish(self) -> None:
        """Complete the file: with all its slots written it is; with fewer, the file of those levels is written beside
        it (one field at a time, read back from it) and renamed over it."""
        n = len(self.grids)
        try:
            if n < self.slots:
                self._write_staged_part(n)
                self._rewrite(n)
        finally:
            self.drop()

    def _write_staged_part(self, n: int) -> None:
        """A part left half assembled (a chunk closed early) written, if it holds complete levels, so that they can be
        read back."""
        if self._buf is not None and n and self.plan.part_of[n - 1] == self._part:
            self._write_staged()
        self._buf = None

    def _rewrite(self, n: int) -> None:
        full, part = self.plan, self.template(n)
        tmp = self.path.with_name(self.path.stem + "_part.h5")  # levels_*.h5: removed by a restart if left by a kill
        fd = None
        try:
            fd = os.open(tmp, os.O_WRONLY | os.O_CREAT | os.O_TRUNC, 0o644)
            for meta in part.meta:  # per part of the file (a part may hold several slots)
                for offset, data in meta:
                    _pwrite(fd, data, offset, tmp)
            for slot in range(n):
                for name, (offset, count) in part.where[slot].items():
                    if count:
                        _pwrite(fd, os.pread(self.fd, count * full.dtype.itemsize, full.where[slot][name][0]), offset,
                                tmp)
            os.close(fd)
            fd = None
            os.replace(tmp, self.path)
        except BaseException:
            if fd is not None:
                os.close(fd)
            _remove(tmp)
            raise

    def drop(self) -> None:
        """Close the file as it is (a failed or killed chunk: left unlisted)."""
        self._buf = None
        if self.fd is not None:
            fd, self.fd = self.fd, None
            try:
                os.close(fd)
            except OSError:
                pass


class _Settler:
    """A thread that settles closed chunks: ``fdatasync``, then their pages dropped from the page cache.

    Without it the kernel keeps GBs of written pages dirty and writes them back late in a long
    run, where its work slows the solver's memory-bound solves (docs/developer/design-notes.md).
    Both calls release the GIL. Not needed for crash safety; a failure is kept and reported.
    """

    def __init__(self) -> None:
        self.paths: queue.Queue = queue.Queue()
        self.error: OSError | None = None
        self.thread = threading.Thread(target=self._loop, name="xdmf-settler", daemon=True)
        self.thread.start()

    def _loop(self) -> None:
        while (path := self.paths.get()) is not None:
            try:
                fd = os.open(path, os.O_RDONLY)
                try:
                    os.fdatasync(fd)
                    os.posix_fadvise(fd, 0, 0, os.POSIX_FADV_DONTNEED)
                finally:
                    os.close(fd)
            except OSError as exc:
                self.error = self.error or exc

    def submit(self, path: Path) -> None:
        self.paths.put(path)

    def stop(self) -> None:
        self.paths.put(None)
        self.thread.join()


class XDMFSeries:
    """A time series of fields on one mesh, appended level by level (collective: call on every rank).

    ``write(t, values)`` takes, for every field, this rank's owned rows in the :class:`Layout`'s
    order (``(rows, components)``, or ``(rows,)`` for scalars). Rank 0 gathers and writes.
    """

    BLOCK = 65536  # cells a block of the set-up's topology lookup

    def __init__(self, directory: str | Path, layout: Layout, fields: Sequence[FieldSpec], precision: str = "double",
                 keep_until: float | None = None, name: str = "solution") -> None:
        if precision not in PRECISIONS:
            raise ValueError(f"precision {precision!r}: one of {', '.join(PRECISIONS)}")
        names = [f.name for f in fields]
        if len(set(names)) != len(names) or not fields:
            raise ValueError(f"fields {names}: at least one, no name twice")
        self.directory = Path(directory)
        self.layout = layout
        self.comm = layout.comm
        self.fields = list(fields)
        self.precision = precision
        self.dtype = PRECISIONS[precision]
        self.name = name
        self.path = self.directory / f"{name}.xdmf"
        self.tmp = self.directory / f".{name}.xdmf.tmp"  # not *.xdmf: no second file a user could open
        self.data_dir = self.directory / "fields"
        self.prefix = "" if name == "solution" else f"{name}_"  # fields/mesh.h5, fields/contact_mesh.h5, ...
        self.grids: list[str] = []  # the XML of every listed level
        self.times: list[float] = []  # their times
        self.chunk: _Chunk | None = None  # rank 0: the chunk being filled (in memory)
        self.error: tuple[str, float | None] | None = None  # rank 0: a failed write; the series takes no more
        self.closed = False
        self._take: dict[str, np.ndarray] | None = None
        self._settler: _Settler | None = None
        self._templates: dict[int, _Template] = {}  # rank 0: the chunk files' templates, by levels
        self._setup_gather()
        self._local = [layout.local[f.center] for f in self.fields]  # this rank's rows of each field
        self._expected = [(f, n, n * f.ncomp) for f, n in zip(self.fields, self._local)]  # ... and values
        self._grid_format = self._grid_xml()
        self._collective(lambda: self._open(keep_until))
        # the mesh is in its file now: neither the whole gathered mesh (rank 0) nor this rank's part is kept
        self.points = self.cells = None
        self.layout = dataclasses.replace(layout, points=None, cells=None)

    # ------------------------------------------------------------------ set-up

    def _setup_gather(self) -> None:
        """Gather every rank's keys once; rank 0 keeps, per rank, the file rows of its owned nodes and cells."""
        comm, lay = self.comm, self.layout
        local = lay.local
        if comm.size > 1:
            keys = comm.gather((lay.node_keys, lay.cell_keys), root=0)
            mesh = comm.gather((lay.points, lay.cells), root=0)
        else:  # one process: its own arrays (a gather pickles copies of them)
            keys, mesh = [(lay.node_keys, lay.cell_keys)], [(lay.points, lay.cells)]
        self.rows_of: list[dict[str, np.ndarray]] = []
        if comm.rank == 0:
            all_nodes = np.concatenate([k[0] for k in keys])
            all_cells = np.concatenate([k[1] for k in keys])
            node_sorted, cell_sorted = np.unique(all_nodes), np.unique(all_cells)
            unique = len(node_sorted) == len(all_nodes) and len(cell_sorted) == len(all_cells)
            for nk, ck in keys:  # file row = rank of the key among all keys: input order, compacted
                self.rows_of.append({"Node": np.searchsorted(node_sorted, nk), "Cell": np.searchsorted(cell_sorted, ck)})
            lay.counts = {"Node": len(node_sorted), "Cell": len(cell_sorted)}
            gdim = lay.points.shape[1] if lay.points.ndim == 2 else 0
            gdim = max([m[0].shape[1] for m in mesh if m[0].size] + [gdim])
            self.points = np.zeros((lay.counts["Node"], gdim))
            self.cells = np.zeros((lay.counts["Cell"], lay.cells.shape[1]), dtype=np.int64)
            for (pts, cells), rows in zip(mesh, self.rows_of):
                self.points[rows["Node"]] = pts
                for start in range(0, len(cells), self.BLOCK):  # the cells' node rows a block at a time
                    block = slice(start, start + self.BLOCK)
                    self.cells[rows["Cell"][block]] = np.searchsorted(node_sorted, cells[block])
        if not comm.bcast(unique if comm.rank == 0 else None, root=0):
            raise ValueError("XDMF writer: a node or cell is owned by two ranks (keys not unique)")
        lay.counts = comm.bcast(lay.counts, root=0)
        self.send_counts = comm.gather(sum(local[f.center] * f.ncomp for f in self.fields), root=0)


    def _collective(self, action) -> None:
        """Run ``action`` on rank 0; raise its failure (as SeriesError) on every rank."""
        error = None
        if self.comm.rank == 0:
            try:
                action()
            except Exception as exc:  # noqa: BLE001  (any failure on rank 0 must reach every rank, or they hang)
                error = (self._describe(exc), getattr(exc, "t", None))
        error = self.comm.bcast(error, root=0) if self.comm.size > 1 else error
        if error is not None:
            raise SeriesError(*error)

    def _describe(self, exc: BaseException) -> str:
        if isinstance(exc, SeriesError):
            return str(exc)
        if isinstance(exc, OSError):
            return describe_oserror(exc) + ("" if _filename(exc) else f" (writing in {self.directory})")
        return f"{type(exc).__name__}: {exc}"

    def _open(self, keep_until: float | None) -> None:
        self.data_dir.mkdir(parents=True, exist_ok=True)
        self.tmp.unlink(missing_ok=True)  # left by a kill during a rewrite; the real file is intact
        if keep_until is not None and self.path.exists():
            self._continue(keep_until)
        else:
            for stale in self.data_dir.glob(f"{self.prefix}levels_*.h5"):
                stale.unlink()
            self.path.unlink(missing_ok=True)
            self._write_mesh()

    def _write_mesh(self) -> None:
        path = self.data_dir / f"{self.prefix}mesh.h5"
        tmp = self.data_dir / f".{self.prefix}mesh.h5.tmp"
        with h5py.File(tmp, "w") as h5:
            h5.create_dataset("geometry", data=self.points.astype("<f8", copy=False))
            h5.create_dataset("topology", data=self.cells.astype("<i8", copy=False))
        os.replace(tmp, path)

    def _continue(self, keep_until: float) -> None:
        """Keep the levels with t <= keep_until of the existing series, check its mesh, drop unlisted chunks."""
        mesh = self.data_dir / f"{self.prefix}mesh.h5"
        if not mesh.exists():
            raise SeriesError(f"{self.path} has no {mesh} (written by an older version?): cannot continue it")
        with h5py.File(mesh, "r") as h5:
            x, cells = h5["geometry"][...], h5["topology"][...]
        scale = max(1.0, float(np.abs(self.points).max(initial=0.0)))
        if x.shape != self.points.shape or cells.shape != self.cells.shape or not np.array_equal(cells, self.cells) \
                or not np.allclose(x, self.points, rtol=0, atol=1e-12 * scale):
            raise SeriesError(f"{mesh} holds another mesh than this run's: cannot continue {self.path}")
        try:
            root = ET.parse(self.path).getroot()
        except ET.ParseError as exc:
            raise SeriesError(f"{self.path}: not readable XML ({exc})") from None
        tol = 1e-12 * max(1.0, abs(keep_until))
        kept = [g for g in root.find("Domain/Grid").findall("Grid") if float(g.find("Time").get("Value")) <= keep_until + tol]
        referenced = set()
        for g in kept:
            ET.indent(g, space="  ", level=3)
            g.tail = "\n"
            self.grids.append("      " + ET.tostring(g, encoding="unicode"))
            self.times.append(float(g.find("Time").get("Value")))
            referenced |= {item.text.strip().split(":", 1)[0] for item in g.iter("DataItem")}
        self._write_xml(self.grids)
        for chunk in self.data_dir.glob(f"{self.prefix}levels_*.h5"):  # a new chunk is named after len(kept): no clash
            if f"fields/{chunk.name}" not in referenced:
                chunk.unlink()

    # ------------------------------------------------------------------ writing

    def write(self, t: float, values: Mapping[str, np.ndarray], left: int | None = None) -> None:
        """Append level ``t`` with every field's owned rows (collective). ``left``: the levels the series will be
        given up to its next :meth:`flush` or :meth:`close`, this one included (None: not known). A chunk opened
        with this level then holds at most that many, so that it is full when the flush closes it, and is not
        written a second time as the file of fewer levels (the same file, written once)."""
        if self.closed:
            raise RuntimeError("write() after close()")
        parts = []
        for f, n, size in self._expected:
            v = values[f.name]
            if not isinstance(v, np.ndarray):
                v = np.asarray(v)
            if v.size != size:
                raise ValueError(f"field {f.name}: {v.shape} values for {n} rows of {f.ncomp} components")
            parts.append((v if v.dtype == self.dtype else v.astype(self.dtype)).ravel())
        comm = self.comm
        if comm.size > 1:  # one Gatherv of the level: its buffer on each rank, the gathered level on rank 0
            buf = np.concatenate(parts) if len(parts) > 1 else parts[0]
            recv = np.empty(sum(self.send_counts), dtype=self.dtype) if comm.rank == 0 else None
            comm.Gatherv(np.ascontiguousarray(buf), (recv, self.send_counts) if comm.rank == 0 else None, root=0)
            del buf
        else:  # one process: each field's own rows, no level buffer
            recv = parts
        self._collective(lambda: self._write_level(float(t), recv, left))

    def flush(self) -> None:
        """List every level written so far: close the open chunk and replace the XML (collective).

        The stepper calls it before a checkpoint, so that a checkpoint never runs ahead of the listed series."""
        def flush() -> None:
            self._raise_error()
            self._list_open_chunk()

        if not self.closed:
            self._collective(flush)

    def _rows(self) -> dict[str, np.ndarray]:
        """Rank 0: per field, where its values in file order are (computed once): in the gathered buffer (several
        ranks), or in the field's own array (one process: no level buffer)."""
        if self._take is None:
            self._take = {}
            pos = 0
            for rows in self.rows_of:
                for f in self.fields:
                    if self.comm.size == 1:
                        pos = 0
                    r = rows[f.center]
                    take = self._take.setdefault(f.name, np.empty(self.layout.counts[f.center] * f.ncomp, np.int64))
                    take.reshape(-1, f.ncomp)[r] = pos + np.arange(len(r) * f.ncomp).reshape(-1, f.ncomp)
                    pos += len(r) * f.ncomp
        return self._take

    def _write_level(self, t: float, recv: np.ndarray | list[np.ndarray], left: int | None = None) -> None:
        """Rank 0: a level into the open chunk (a new chunk if none is open, of at most ``left`` levels); a full chunk
        is listed at once."""
        self._raise_error()
        try:
            if self.chunk is None:
                first = len(self.grids)
                slots = self._chunk_slots() if left is None else max(1, min(self._chunk_slots(), left))
                self.chunk = _Chunk(self.data_dir / f"{self.prefix}levels_{first:06d}.h5", first, slots,
                                    self._template)
            self.chunk.add(t, recv, self._rows(), self._grid_format)
        except Exception as exc:
            try:
                self._list_open_chunk()  # its complete levels, if they can still be written
            except SeriesError:
                pass
            self.error = (self._describe(exc), t)  # the first failure is the one reported
            raise SeriesError(*self.error) from None
        if self.chunk.full:
            self._list_open_chunk()

    def _raise_error(self) -> None:
        self._raise_settled()
        if self.error is not None:
            raise SeriesError(*self.error)

    def _raise_settled(self) -> None:
        if self._settler is not None and self._settler.error is not None:
            raise SeriesError(self._describe(self._settler.error))

    def _template(self, slots: int) -> _Template:
        """The :class:`_Template` of a chunk of ``slots`` levels (made once)."""
        if slots not in self._templates:
            self._templates[slots] = _Template(self.fields, self.layout.counts, self.dtype, slots)
        return self._templates[slots]

    def _chunk_slots(self) -> int:
        """Levels per chunk: ``MAX_LEVELS_PER_CHUNK``, fewer if they would exceed ``CHUNK_BYTES``."""
        level_bytes = sum(self.layout.counts[f.center] * f.ncomp * self.dtype.itemsize for f in self.fields)
        return max(1, min(MAX_LEVELS_PER_CHUNK, CHUNK_BYTES // max(1, level_bytes)))

    def _list_open_chunk(self) -> None:
        """Rank 0: write the open chunk's file, then list its levels (the XML replaced), then settle it in the
        background. A failure (the chunk file removed, the series takes no more levels) is a SeriesError with
        the time of the chunk's last level."""
        chunk, self.chunk = self.chunk, None
        if chunk is None:
            return
        if not chunk.grids:  # its first level failed: nothing to list
            chunk.drop()
            _remove(chunk.path)
            return
        try:
            _close_chunk(chunk)
            self._write_xml(self.grids + chunk.grids)
        except Exception as exc:
            self.error = (self._describe(exc), chunk.times[-1])
            _remove(chunk.path)  # not listed: the space back for what follows (the checkpoint, the CSV)
            raise SeriesError(*self.error) from None
        self.grids += chunk.grids
        self.times += chunk.times
        if SETTLE_CHUNKS and not self.closed:
            if self._settler is None:
                self._settler = _Settler()
            self._settler.submit(chunk.path)

    def _write_xml(self, grids: list[str]) -> None:
        """Replace ``solution.xdmf`` by the list of ``grids`` (none: no file)."""
        if not grids:
            self.path.unlink(missing_ok=True)
            return
        text = _HEAD.format(name=self.name) + "".join(grids) + _TAIL
        _replace_file(self.path, self.tmp, text.encode())


    def _grid_xml(self) -> str:
        """The XML of one level with placeholders {t}, {file}, {slot}: topology and geometry from the mesh file."""
        lay = self.layout
        nn, nc = lay.counts["Node"], lay.counts["Cell"]
        npc = self.cells.shape[1] if self.comm.rank == 0 else 0
        gdim = self.points.shape[1] if self.comm.rank == 0 else 0
        p = self.dtype.itemsize
        lines = [
            f'      <Grid Name="{self.name}" GridType="Uniform">',
            f'        <Topology TopologyType="{lay.cell_type}" NumberOfElements="{nc}" NodesPerElement="{npc}">',
            f'          <DataItem Dimensions="{nc} {npc}" NumberType="Int" Precision="8" Format="HDF">'
            f"fields/{self.prefix}mesh.h5:/topology</DataItem>",
            "        </Topology>",
            f'        <Geometry GeometryType="{"XYZ" if gdim == 3 else "XY"}">',
            f'          <DataItem Dimensions="{nn} {gdim}" NumberType="Float" Precision="8" Format="HDF">'
            f"fields/{self.prefix}mesh.h5:/geometry</DataItem>",
            "        </Geometry>",
            '        <Time Value="{t}"/>',
        ]
        for f in self.fields:
            n = lay.counts[f.center]
            dims = f"{n}" if f.ncomp == 1 else f"{n} {f.ncomp}"
            lines += [
                f'        <Attribute Name="{f.name}" AttributeType="{f.kind}" Center="{f.center}">',
                f'          <DataItem Dimensions="{dims}" NumberType="Float" Precision="{p}" Format="HDF">'
                f"{{file}}:/{{slot}}/{f.name}</DataItem>",
                "        </Attribute>",
            ]
        lines.append("      </Grid>\n")
        return "\n".join(lines)

    # ------------------------------------------------------------------ closing

    def close(self) -> None:
        """List the open chunk's levels and stop the settling thread (collective; idempotent).

        Raises a failure of that last listing; a failure already raised by ``write`` is not raised again.
        """
        if self.closed:
            return
        self.closed = True

        def finish() -> None:
            try:
                if self.error is None:  # after a failed write, the open chunk was listed (or dropped) then
                    self._list_open_chunk()
            finally:
                self._templates.clear()
                if self._settler is not None:
                    self._settler.stop()
            self._raise_settled()

        self._collective(finish)


def _filename(exc: OSError) -> str | None:
    """The file an OSError is about; h5py's errors name it only inside HDF5's message."""
    if exc.filename:
        return exc.filename
    found = re.search(r"filename = '([^']*)'", str(exc))
    return found.group(1) if found else None


def describe_oserror(exc: OSError) -> str:
    """``No space left on device (results/fields/levels_000100.h5)``: the reason and the file, on one line
    (h5py's errors carry HDF5's multi-line message: the reason is taken from their errno)."""
    reason = os.strerror(exc.errno) if exc.errno else (exc.strerror or str(exc)).splitlines()[0]
    name = _filename(exc)
    return f"{reason} ({name})" if name else reason


def read_series(path: str | Path, values: bool = True) -> dict:
    """Read a series back with h5py (independently of the writer): points, cells, times, {field: [values per time]}
    (None at a time that lacks the field: a restart may change ``output.fields``).

    Everything the XML names is checked, so that a damaged results directory is one :class:`ResultsError` naming
    the file and what is wrong (a truncated or missing ``.h5``, a missing dataset, a shape other than the XML's,
    malformed XML, cells naming nodes that do not exist) and never a library's traceback. ``values=False`` checks
    the field datasets' presence and shapes without reading them (their entries are then None): what a renderer
    that reads the files itself (ParaView) needs to know first."""
    path = Path(path)
    with _Items(path, values) as items:
        grids = items.grids()
        out: dict = {"times": [], "fields": {}}
        for i, g in enumerate(grids):
            if i == 0:
                out["points"] = items.load(g.find("Geometry/DataItem"), "geometry", numeric="f")
                out["cells"] = items.load(g.find("Topology/DataItem"), "topology", numeric="iu")
                _check_mesh(items.path, out["points"], out["cells"])
            else:  # every level names its mesh again: ParaView reads each (and aborts on a missing one)
                for tag, key, numeric in (("Geometry", "points", "f"), ("Topology", "cells", "iu")):
                    shape = items.load(g.find(f"{tag}/DataItem"), f"{tag.lower()} at level {i}", numeric=numeric,
                                       read=False).shape
                    if shape != out[key].shape:
                        raise ResultsError(path, f"{tag.lower()} at level {i}: shape {shape}, level 0's is "
                                                 f"{out[key].shape}")
            out["times"].append(items.time(g, i))
            for att in g.findall("Attribute"):
                name = att.get("Name")
                if not name:
                    raise ResultsError(path, f"level {i}: an Attribute without a Name")
                data = items.load(att.find("DataItem"), f"field {name} at level {i}", read=values)
                if data.shape[:1] not in ((len(out["points"]),), (len(out["cells"]),)):
                    raise ResultsError(path, f"field {name} at level {i}: {data.shape[0] if data.shape else 0} rows, "
                                             f"neither the {len(out['points'])} nodes nor the {len(out['cells'])} cells")
                field_values = out["fields"].setdefault(name, [])
                field_values += [None] * (i - len(field_values)) + [data if values else None]
        for field_values in out["fields"].values():
            field_values += [None] * (len(out["times"]) - len(field_values))
    return out


def _check_mesh(path: Path, points: np.ndarray, cells: np.ndarray) -> None:
    """Nodes as rows of 2 or 3 finite coordinates; cells as segments (a boundary's, in 2-D), triangles or tetrahedra
    naming existing nodes."""
    if points.ndim != 2 or points.shape[1] not in (2, 3) or not np.isfinite(points).all():
        raise ResultsError(path, f"geometry: {points.shape} coordinates, not finite rows of 2 or 3")
    if cells.ndim != 2 or cells.shape[1] not in (2, 3, 4) or len(cells) == 0:
        raise ResultsError(path, f"topology: shape {cells.shape}, not rows of 2 (segments), 3 (triangles) or 4 "
                                 "(tetrahedra) nodes")
    if cells.min() < 0 or cells.max() >= len(points):
        raise ResultsError(path, f"topology: node numbers {cells.min()}..{cells.max()} outside the {len(points)} nodes")


class _Items:
    """The XML of a series and the HDF5 files its DataItems name, opened once each (closed on leaving)."""

    def __init__(self, path: Path, values: bool) -> None:
        self.path, self.values, self.files = path, values, {}

    def __enter__(self) -> _Items:
        return self

    def __exit__(self, *exc) -> None:
        for f in self.files.values():
            f.close()

    def grids(self) -> list:
        """The time levels' Grid elements."""
        try:
            root = ET.parse(self.path).getroot()
        except ET.ParseError as exc:
            raise ResultsError(self.path, f"not readable XML ({exc})") from None
        except OSError as exc:
            raise ResultsError(self.path, f"cannot be read ({exc.strerror or exc})") from None
        collection = root.find("Domain/Grid")
        grids = [] if collection is None else collection.findall("Grid")
        if not grids:
            raise ResultsError(self.path, "lists no time levels (no Domain/Grid/Grid elements)")
        return grids

    def time(self, grid, i: int) -> float:
        """The level's time value (finite)."""
        element = grid.find("Time")
        try:
            t = float(element.get("Value"))
        except (AttributeError, TypeError, ValueError):
            raise ResultsError(self.path, f"level {i}: no time value (a Time element with a number)") from None
        if not np.isfinite(t):
            raise ResultsError(self.path, f"level {i}: time value {t}")
        return t

    def _file(self, name: str):
        if name not in self.files:
            target = self.path.parent / name
            if not target.is_file():
                raise ResultsError(target, f"does not exist (named by {self.path.name})")
            try:
                self.files[name] = h5py.File(target, "r")
            except OSError as exc:  # truncated, not HDF5, unreadable
                raise ResultsError(target, f"not a readable HDF5 file ({str(exc).splitlines()[0]})") from None
        return self.files[name]

    def load(self, item, what: str, numeric: str = "iuf", read: bool = True) -> np.ndarray:
        """The array a DataItem names (``FILE.h5:/DATASET``), of the shape the XML says; ``read=False``: zeros of
        that shape, taking no memory (the dataset's presence, shape and type checked, its values not read)."""
        text = "" if item is None or item.text is None else item.text.strip()
        name, sep, dataset = text.partition(":")
        if not (name and sep and dataset):
            raise ResultsError(self.path, f"{what}: the DataItem names no FILE.h5:/DATASET ({text[:80]!r})")
        try:
            dims = tuple(int(d) for d in item.get("Dimensions", "").split())
        except ValueError:
            raise ResultsError(self.path, f"{what}: Dimensions {item.get('Dimensions')!r} are not integers") from None
        target, h5 = self.path.parent / name, self._file(name)
        try:
            data = h5.get(dataset)
        except (ValueError, TypeError, KeyError, OSError) as exc:  # a damaged (truncated) group, a bad name
            reason = str(exc).splitlines()[0] if str(exc) else type(exc).__name__
            raise ResultsError(target, f"{dataset} cannot be looked up: damaged or truncated? ({reason})") from None
        if not isinstance(data, h5py.Dataset):
            raise ResultsError(target, f"has no dataset {dataset} ({what}, named by {self.path.name})")
        if data.shape != dims or data.dtype.kind not in numeric:
            raise ResultsError(target, f"{dataset}: {data.dtype} of shape {data.shape}, {self.path.name} says "
                                       f"{'numbers' if numeric == 'iuf' else 'integers' if 'i' in numeric else 'floats'}"
                                       f" of shape {dims}")
        if not read:
            return np.broadcast_to(np.zeros((), data.dtype), dims)
        try:
            return data[...]
        except (OSError, ValueError) as exc:  # a damaged chunk
            raise ResultsError(target, f"{dataset}: cannot be read ({str(exc).splitlines()[0]})") from None
