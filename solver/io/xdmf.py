"""XDMF time series whose cost per written level does not grow with the run, and that a SIGKILL cannot damage.

Layout of a results directory (``name`` = ``solution``)::

    solution.xdmf              one temporal collection; each written level is one <Grid> with every field
    fields/mesh.h5             /geometry, /topology: written once
    fields/levels_000000.h5    /0000/<field>, /0001/<field>, ...: levels 0, 1, ... of the series
    fields/levels_000100.h5    /0000/<field> is level 100, ... (a chunk holds up to 100 levels, 256 MiB)

**Order.** Nodes and cells are written in the mesh's input order (``input_global_indices``,
``original_cell_index``), gathered to rank 0. The files therefore do not depend on the
partition: one process and ``mpirun -n N`` write the same rows, and a restart on another
number of ranks continues the same series on the same mesh file.

**Cost per level.** Rank 0 writes the level's values with one ``pwrite`` per field into
space that HDF5 allocated when the chunk was created, then appends the level's ``<Grid>``
to the XML. Nothing already written is read, parsed or rewritten. HDF5 itself makes one
chunk per run (a template, about 35 us per dataset); every chunk file is a copy of the
template's metadata bytes (a few us per level it holds).

**In the background.** Levels of ``BACKGROUND_BYTES`` or more are written by one thread on
rank 0, in the order they were asked for, while the solver computes the next levels
(``pwrite`` releases the GIL); smaller ones are written at once, since handing them over costs
more than writing them.
Once the kernel holds a few GB of unwritten pages it makes ``pwrite`` wait for the disk
(measured: 0.1 ms per MB at first, 0.6 ms after 2 GB); the thread takes that wait off
the time loop. At most ``QUEUE_LEVELS`` levels wait for it (then ``write`` waits: the
memory stays bounded). A write that fails is reported by the next ``write``, ``flush``
or ``close`` as a :class:`SeriesError` that carries the failed level's time ``t``; the
levels after it are dropped, so the series still lists only complete levels, in order.
``flush()`` waits for every level asked for (the stepper calls it before a checkpoint,
so that a checkpoint never runs ahead of the written series).

**Crash safety (process death: SIGKILL, OOM killer, a cancelled job).** A level becomes
visible only after its data are in the file.
- *Data.* A chunk's HDF5 metadata is complete, and the file closed, before any level is
  written into it: every dataset is contiguous and allocated at creation
  (``H5D_ALLOC_TIME_EARLY``, no fill). The data of a level are then raw ``pwrite`` calls
  into that dataset's region, outside the HDF5 library, so a kill inside a write can only
  leave a partly written region of the one level not yet listed. HDF5's own metadata is
  never touched again (an HDF5 file that is open for writing can be left unreadable by a
  kill: the failure mode of the earlier layout).
- *XML.* ``solution.xdmf`` ends in a processing instruction padded with spaces
  (``<?pad ...?>``), valid after the root element. A new grid is written into that padding
  (where it is inert), then made live by changing one byte: the space in front of the
  text ``!--`` before the closing tags becomes ``<``, which turns the old closing tags
  into a comment that ends just before the new grid. Every state of the file, at every
  byte, is valid XML listing only complete levels. When the padding runs out (it is sized
  for the expected number of levels), the file is rewritten to a new name and renamed
  (amortized O(1)); ``close()`` rewrites it once the same way without padding and markers.
Writes are not ``fsync``ed: they survive the death of the process, not of the machine.

**Why not something simpler.** Appending datasets through an open HDF5 file (flushed after
each level) leaves a window in which a kill corrupts the file's metadata, and with it levels
already listed. HDF5's SWMR mode keeps the file consistent but cannot create datasets, and a
killed writer leaves a flag that stops readers (``h5clear``). One HDF5 file per level is
safe but makes thousands of files, and meshio's reader keeps each one open (past the usual
limit of 1024 descriptors). Rewriting only the closing tags in one ``write`` is not atomic
when the write spans two pages. Parallel HDF5 (``python3-h5py-mpi``) would add a package
and still need the rows put into a partition-independent order; gathering to rank 0 costs
less than the write itself here (measured by ``solver bench``: the files of 1 and 2 ranks
agree to round-off, and the 2-rank write time per level is the serial one).

**Restart.** ``XDMFSeries(..., keep_until=t)`` keeps the levels with time <= t, checks
that ``fields/mesh.h5`` is this mesh, removes the data chunks no kept level refers to, and
appends after the kept levels.

This module needs numpy, h5py and mpi4py; dolfinx only for :func:`dolfinx_layout`.
"""

from __future__ import annotations

import os
import queue
import re
import signal
import threading
import xml.etree.ElementTree as ET
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

PRECISIONS = {"double": np.dtype("<f8"), "single": np.dtype("<f4")}
KINDS = {"Scalar": 1, "Vector": 3, "Tensor6": 6}  # components in the file
CENTERS = ("Node", "Cell")
CELL_TYPES = {("triangle", 3): "Triangle", ("tetrahedron", 4): "Tetrahedron"}
MAX_LEVELS_PER_CHUNK = 100
QUEUE_LEVELS = 4  # levels that may wait for the background writer (rank 0)
BACKGROUND_BYTES = 256 * 2**10  # levels of at least this size are written in the background (see _submit)
BACKGROUND_ENV = "SOLVER_TEST_BACKGROUND"  # test hook: "1" writes every level in the background
FLUSH_CHUNKS = True  # see _retire
CHUNK_BYTES = 256 * 2**20
KILL_ENV = "SOLVER_TEST_KILL"  # test hooks: "stage:k" SIGKILLs this process inside its k-th write of stage,
ENOSPC_ENV = "SOLVER_TEST_ENOSPC"  # or fails it there with OSError ENOSPC, as a full disk does (see _Hook)

_HEAD = ('<?xml version="1.0"?>\n<!DOCTYPE Xdmf SYSTEM "Xdmf.dtd" []>\n<Xdmf Version="3.0">\n  <Domain>\n'
         '    <Grid Name="{name}" GridType="Collection" CollectionType="Temporal">\n')
_TAIL = "    </Grid>\n  </Domain>\n</Xdmf>\n"
_MARK = " !--"  # text before the closing tags; its first byte becomes "<" to retire them
_PAD_OPEN = "<?pad "
_PAD_CLOSE = "?>\n"
_REOPEN = " -->\n"  # first bytes of an appended unit: ends the comment that retires the old closing tags


class SeriesError(RuntimeError):
    """Writing or continuing the series failed; the message is one line for the user.

    ``t`` is the time of the level whose write failed (None: not a level's write)."""

    def __init__(self, message: str, t: float | None = None) -> None:
        super().__init__(message)
        self.t = t


class _Worker:
    """One background thread that runs jobs in order; after a failure it drops the rest and keeps the error."""

    def __init__(self) -> None:
        self.jobs: queue.Queue = queue.Queue(maxsize=QUEUE_LEVELS)
        self.error: BaseException | None = None
        self.error_t: float | None = None
        self.thread = threading.Thread(target=self._loop, name="xdmf-writer", daemon=True)
        self.thread.start()

    def _loop(self) -> None:
        while True:
            job = self.jobs.get()
            try:
                if job is None:
                    return
                if self.error is None:
                    t, action = job
                    try:
                        action()
                    except BaseException as exc:  # noqa: BLE001  (kept, and raised in the main thread)
                        self.error, self.error_t = exc, t
            finally:
                self.jobs.task_done()

    def submit(self, t: float, action) -> None:
        self.jobs.put((t, action))

    def wait(self) -> None:
        self.jobs.join()

    def stop(self) -> None:
        self.jobs.put(None)
        self.thread.join()


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
    points: np.ndarray  # (owned nodes, gdim)
    node_keys: np.ndarray  # (owned nodes,)
    cells: np.ndarray  # (owned cells, nodes per cell), node keys
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
    rows = rows.reshape(len(rows), -1)
    if rows.shape[1] == 3:
        return rows
    out = np.zeros((len(rows), 3), dtype=rows.dtype)
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


class _Hook:
    """Test hook: ``SOLVER_TEST_KILL=stage:k`` SIGKILLs this process in the middle of its k-th write of
    ``stage``; ``SOLVER_TEST_ENOSPC=stage:k`` raises OSError ENOSPC there instead.

    Stages: ``data`` (half of a level's first field written), ``xml`` (half of the grid written
    into the padding), ``flip`` (grid written, not yet made live), ``chunk`` (a new chunk file
    half copied). Counts are per writer, from 1.
    """

    def __init__(self) -> None:
        spec = os.environ.get(KILL_ENV, "")
        self.enospc = not spec
        spec = spec or os.environ.get(ENOSPC_ENV, "")
        self.stage, _, k = spec.partition(":")
        self.at = int(k) if k.isdigit() else 0
        self.counts: dict[str, int] = {}

    def armed(self, stage: str) -> bool:
        if stage != self.stage:
            return False
        self.counts[stage] = self.counts.get(stage, 0) + 1
        return self.counts[stage] == self.at

    def kill(self) -> None:
        if self.enospc:
            raise OSError(28, "No space left on device (test hook)", None)
        os.kill(os.getpid(), signal.SIGKILL)


def _pwrite_all(fd: int, data, offset: int) -> None:
    """``pwrite`` all of ``data`` (a short write is retried; a full disk raises OSError ENOSPC)."""
    view = memoryview(data).cast("B")
    while len(view):
        n = os.pwrite(fd, view, offset)
        if n <= 0:
            raise OSError(28, "No space left on device (short write)")
        view, offset = view[n:], offset + n


def _retire(fd: int) -> None:
    """Close a full chunk after its pages are on disk and out of the page cache (background writer).

    Otherwise the kernel keeps GBs of written pages dirty and writes them back late in a long
    run, where its work slows the solver's memory-bound solves (measured: n = 128, 2,000
    levels, the displacement solve 4.7 -> 6.6 ms per step by the end). Flushing each chunk as
    it fills spreads that work evenly over the run.
    """
    try:
        if FLUSH_CHUNKS:
            os.fdatasync(fd)
            os.posix_fadvise(fd, 0, 0, os.POSIX_FADV_DONTNEED)
    finally:
        os.close(fd)


def _fmt_time(t: float) -> str:
    return repr(float(t))


@dataclass
class _Template:
    slots: int
    size: int  # bytes of the file
    meta: list[tuple[int, bytes]]  # (offset, bytes) of everything that is not a dataset's data
    offsets: list[dict[str, int]]  # per slot: field -> byte offset of its data


@dataclass
class _Chunk:
    first: int  # series index of its first slot
    slots: int
    path: Path
    fd: int
    offsets: list[dict[str, int]]  # per slot: field -> byte offset of its data


class XDMFSeries:
    """A time series of fields on one mesh, appended level by level (collective: call on every rank).

    ``write(t, values)`` takes, for every field, this rank's owned rows in the :class:`Layout`'s
    order (``(rows, components)``, or ``(rows,)`` for scalars). Rank 0 gathers and writes.
    """

    def __init__(self, directory: str | Path, layout: Layout, fields: Sequence[FieldSpec], precision: str = "double",
                 expected_levels: int | None = None, keep_until: float | None = None, name: str = "solution") -> None:
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
        self.hook = _Hook()
        self.grids: list[str] = []  # the XML of every listed level
        self.times: list[float] = []
        self.chunk: _Chunk | None = None
        self.fd: int | None = None  # solution.xdmf in padded form, open for pwrite
        self.flip = self.cursor = self.pad_end = 0
        self.closed = False
        self.expected_new = expected_levels
        self.base = 0  # levels kept from an earlier run
        self._take: dict[str, np.ndarray] | None = None
        self._worker: _Worker | None = None  # rank 0: the background writer, started by the first write
        self._templates: dict[int, _Template] = {}
        self._setup_gather()
        self._grid_format = self._grid_xml()
        self._collective(lambda: self._open(keep_until))
        self._collective(self._prepare_templates)

    @property
    def target(self) -> int | None:
        """Levels the series will hold once this writer has appended the expected ones (None: not known)."""
        return None if self.expected_new is None else self.base + self.expected_new

    # ------------------------------------------------------------------ set-up

    def _setup_gather(self) -> None:
        """Gather every rank's keys once; rank 0 keeps, per rank, the file rows of its owned nodes and cells."""
        comm, lay = self.comm, self.layout
        local = lay.local
        keys = comm.gather((lay.node_keys, lay.cell_keys), root=0)
        mesh = comm.gather((lay.points, lay.cells), root=0)
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
                self.cells[rows["Cell"]] = np.searchsorted(node_sorted, cells)
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
            return describe_oserror(exc) + ("" if exc.filename else f" (writing in {self.directory})")
        return f"{type(exc).__name__}: {exc}"

    def _raise_pending(self) -> None:
        """Rank 0: raise the background writer's failure, if it had one, with the failed level's time."""
        if self._worker is not None and self._worker.error is not None:
            raise SeriesError(self._describe(self._worker.error), self._worker.error_t)

    def _open(self, keep_until: float | None) -> None:
        self.data_dir.mkdir(parents=True, exist_ok=True)
        if self.tmp.exists():
            self.tmp.unlink()  # left by a kill during a rewrite; the real file is intact
        if keep_until is not None and self.path.exists():
            self._continue(keep_until)
        else:
            for stale in self.data_dir.glob("levels_*.h5"):
                stale.unlink()
            if self.path.exists():
                self.path.unlink()
            self._write_mesh()

    def _write_mesh(self) -> None:
        import h5py

        path = self.data_dir / "mesh.h5"
        tmp = self.data_dir / ".mesh.h5.tmp"
        with h5py.File(tmp, "w") as h5:
            h5.create_dataset("geometry", data=self.points.astype("<f8"))
            h5.create_dataset("topology", data=self.cells.astype("<i8"))
        os.replace(tmp, path)

    def _continue(self, keep_until: float) -> None:
        """Keep the levels with t <= keep_until of the existing series, check its mesh, drop unreferenced chunks."""
        import h5py

        mesh = self.data_dir / "mesh.h5"
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
        coll = root.find("Domain/Grid")
        tol = 1e-12 * max(1.0, abs(keep_until))
        kept = [g for g in coll.findall("Grid") if float(g.find("Time").get("Value")) <= keep_until + tol]
        referenced = set()
        for g in kept:
            ET.indent(g, space="  ", level=3)
            g.tail = "\n"
            self.grids.append("      " + ET.tostring(g, encoding="unicode"))
            self.times.append(float(g.find("Time").get("Value")))
            referenced |= {item.text.strip().split(":", 1)[0] for item in g.iter("DataItem")}
        self.base = len(self.grids)
        self._rewrite(padded=True)
        for chunk in self.data_dir.glob("levels_*.h5"):
            if f"fields/{chunk.name}" not in referenced:
                chunk.unlink()

    # ------------------------------------------------------------------ writing

    def write(self, t: float, values: Mapping[str, np.ndarray]) -> None:
        """Append level ``t`` with every field's owned rows (collective)."""
        if self.closed:
            raise RuntimeError("write() after close()")
        parts = []
        for f in self.fields:
            v = np.asarray(values[f.name])
            n = self.layout.local[f.center]
            if v.size != n * f.ncomp:
                raise ValueError(f"field {f.name}: {v.shape} values for {n} rows of {f.ncomp} components")
            parts.append(v.astype(self.dtype, copy=False).ravel())
        buf = np.concatenate(parts) if len(parts) > 1 else parts[0]
        comm = self.comm
        if comm.size > 1:
            recv = np.empty(sum(self.send_counts), dtype=self.dtype) if comm.rank == 0 else None
            comm.Gatherv(np.ascontiguousarray(buf), (recv, self.send_counts) if comm.rank == 0 else None, root=0)
        else:
            recv = buf
        self._collective(lambda: self._submit(float(t), recv))

    def flush(self) -> None:
        """Wait until every level asked for is written (collective); raise a failure of any of them."""
        if self.closed:
            return

        def wait() -> None:
            if self._worker is not None:
                self._worker.wait()
            self._raise_pending()

        self._collective(wait)

    def _submit(self, t: float, recv: np.ndarray) -> None:
        """Rank 0: write the level, or hand it to the background writer (values copied into file order first).

        Small levels are written here: the thread's cost (the GIL passed back and forth, about
        0.3 ms per level, measured at n = 32) exceeds their write, which never waits for the
        disk long. Large ones go to the thread, whose ``pwrite`` may wait for the disk.
        """
        self._raise_pending()
        fields = list(self._global(recv))  # new arrays: the caller may change its own after write() returns
        if self._slot_bytes() < BACKGROUND_BYTES and os.environ.get(BACKGROUND_ENV) != "1":
            self._write_level(t, fields)
            return
        if self._worker is None:
            self._worker = _Worker()
        self._worker.submit(t, lambda: self._write_level(t, fields))

    def _global(self, recv: np.ndarray):
        """Rank 0: each field's values in file order (one gather through an index computed once)."""
        if self._take is None:
            self._take = {}
            pos = 0
            for rows in self.rows_of:
                for f in self.fields:
                    r = rows[f.center]
                    take = self._take.setdefault(f.name, np.empty(self.layout.counts[f.center] * f.ncomp, np.int64))
                    take.reshape(-1, f.ncomp)[r] = pos + np.arange(len(r) * f.ncomp).reshape(-1, f.ncomp)
                    pos += len(r) * f.ncomp
        for f in self.fields:
            yield f.name, recv[self._take[f.name]]

    def _write_level(self, t: float, fields: list[tuple[str, np.ndarray]]) -> None:
        """The background writer: a level's data into its chunk, then its grid into the XML."""
        index = len(self.grids)
        if self.chunk is None or index >= self.chunk.first + self.chunk.slots:
            self._new_chunk(index)
        chunk = self.chunk
        slot = index - chunk.first
        for i, (name, data) in enumerate(fields):
            offset = chunk.offsets[slot][name]
            if i == 0 and self.hook.armed("data"):
                _pwrite_all(chunk.fd, memoryview(data).cast("B")[: data.nbytes // 2], offset)
                self.hook.kill()
            _pwrite_all(chunk.fd, data, offset)
        self._append(self._grid_format.format(t=_fmt_time(t), file=f"fields/{chunk.path.name}", slot=f"{slot:04d}"))
        self.times.append(t)

    def _slot_bytes(self) -> int:
        return sum(self.layout.counts[f.center] * f.ncomp * self.dtype.itemsize for f in self.fields)

    def _template(self, slots: int) -> _Template:
        """An HDF5 chunk of ``slots`` levels made once by HDF5, kept as the bytes that are not data.

        Every dataset is contiguous and allocated at creation without fill, so the file is
        metadata plus one raw region per dataset; copying the metadata bytes into a new file
        of the same size makes another valid chunk without calling HDF5 (which costs about
        35 us per dataset).
        """
        import h5py

        if slots in self._templates:
            return self._templates[slots]
        path = self.data_dir / ".template.h5"
        dcpl = h5py.h5p.create(h5py.h5p.DATASET_CREATE)
        dcpl.set_layout(h5py.h5d.CONTIGUOUS)
        dcpl.set_alloc_time(h5py.h5d.ALLOC_TIME_EARLY)
        dcpl.set_fill_time(h5py.h5d.FILL_TIME_NEVER)
        dcpl.set_obj_track_times(False)
        tid = h5py.h5t.py_create(self.dtype)
        offsets, regions = [], []
        with h5py.File(path, "w") as h5:
            h5.attrs["about"] = ("solver.xdmf chunk: group NNNN holds level (first + NNNN) of the series; "
                                 "only the levels listed in the .xdmf file are complete")
            for s in range(slots):
                group = h5.create_group(f"{s:04d}")
                row = {}
                for f in self.fields:
                    shape = (self.layout.counts[f.center],) if f.ncomp == 1 else (self.layout.counts[f.center], f.ncomp)
                    ds = h5py.h5d.create(group.id, f.name.encode(), tid, h5py.h5s.create_simple(shape), dcpl=dcpl)
                    row[f.name] = ds.get_offset()
                    regions.append((row[f.name], row[f.name] + ds.get_storage_size()))
                offsets.append(row)
        size = path.stat().st_size
        meta, pos = [], 0
        with open(path, "rb") as fh:
            for a, b in [*sorted(regions), (size, size)]:
                if a < pos or b > size:
                    raise SeriesError("HDF5 chunk template: overlapping or truncated data regions")
                if a > pos:
                    fh.seek(pos)
                    meta.append((pos, fh.read(a - pos)))
                pos = b
        path.unlink()
        self._templates[slots] = _Template(slots, size, meta, offsets)
        return self._templates[slots]

    def _chunk_slots(self, first: int) -> int:
        """Levels in the chunk that starts at level ``first``: full chunks, the last one cut to the expected end."""
        slots = max(1, min(MAX_LEVELS_PER_CHUNK, CHUNK_BYTES // max(1, self._slot_bytes())))
        if self.target is not None and self.target > first:
            slots = min(slots, self.target - first)
        return slots

    def _prepare_templates(self) -> None:
        """Make the templates of the expected chunks now, so that no level pays for HDF5 (rank 0)."""
        first = len(self.grids)
        self._template(self._chunk_slots(first))
        if self.target is not None and self.target > first:
            full = self._chunk_slots(first)
            self._template(self._chunk_slots(first + full * ((self.target - first - 1) // full)))

    def _new_chunk(self, first: int) -> None:
        """Create ``levels_<first>.h5`` (a copy of the template's metadata) and keep it open for raw writes."""
        if self.chunk is not None:
            _retire(self.chunk.fd)
            self.chunk = None
        template = self._template(self._chunk_slots(first))
        path = self.data_dir / f"levels_{first:06d}.h5"
        fd = os.open(path, os.O_WRONLY | os.O_CREAT | os.O_TRUNC, 0o644)  # a chunk no listed level refers to
        try:
            os.ftruncate(fd, template.size)
            for i, (offset, data) in enumerate(template.meta):
                if i == len(template.meta) // 2 and self.hook.armed("chunk"):
                    self.hook.kill()
                _pwrite_all(fd, data, offset)
        except BaseException:
            os.close(fd)
            raise
        self.chunk = _Chunk(first, template.slots, path, fd, template.offsets)

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
            "fields/mesh.h5:/topology</DataItem>",
            "        </Topology>",
            f'        <Geometry GeometryType="{"XYZ" if gdim == 3 else "XY"}">',
            f'          <DataItem Dimensions="{nn} {gdim}" NumberType="Float" Precision="8" Format="HDF">'
            "fields/mesh.h5:/geometry</DataItem>",
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

    # ------------------------------------------------------------------ the XML

    def _append(self, grid: str) -> None:
        """List one more grid: write it into the padding (inert), then retire the old closing tags with one byte."""
        if "--" in grid or "?>" in grid:
            raise ValueError("a grid may not contain '--' or '?>'")
        if self.fd is None:  # the first level: the file is created (atomically) with it
            self.grids.append(grid)
            self._rewrite(padded=True)
            return
        unit = (_REOPEN + grid + _MARK + _TAIL + _PAD_OPEN).encode()
        if self.cursor + len(unit) > self.pad_end:  # padding used up: rewrite with more (amortized O(1))
            self.grids.append(grid)
            self._rewrite(padded=True, extra=len(unit))
            return
        if self.hook.armed("xml"):
            _pwrite_all(self.fd, unit[: len(unit) // 2], self.cursor)
            self.hook.kill()
        _pwrite_all(self.fd, unit, self.cursor)
        if self.hook.armed("flip"):
            self.hook.kill()
        _pwrite_all(self.fd, b"<", self.flip)  # the one byte that makes the grid live
        self.grids.append(grid)
        self.flip = self.cursor + len(_REOPEN) + len(grid)
        self.cursor += len(unit)

    def _rewrite(self, padded: bool, extra: int = 0) -> None:
        """Write the whole file (listed grids; padded: plus marker, closing tags and padding) to a new name and rename it."""
        if self.fd is not None:
            os.close(self.fd)
            self.fd = None
        if not self.grids:
            if self.path.exists():
                self.path.unlink()
            return
        head = _HEAD.format(name=self.name) + "".join(self.grids)
        if padded:
            per_level = len(self.grids[-1]) + len(_REOPEN + _MARK + _TAIL + _PAD_OPEN) + 32
            remaining = max(0, self.target - len(self.grids)) if self.target is not None else 0
            reserve = max(remaining * per_level, len(head) + 2 * max(extra, per_level), 4096)  # grow geometrically
            text = head + _MARK + _TAIL + _PAD_OPEN
            body = text.encode()
            data = body + b" " * reserve + _PAD_CLOSE.encode()
        else:
            data = (head + _TAIL).encode()
        fd = os.open(self.tmp, os.O_WRONLY | os.O_CREAT | os.O_TRUNC, 0o644)
        try:
            _pwrite_all(fd, data, 0)
        except BaseException:
            os.close(fd)
            self.tmp.unlink(missing_ok=True)
            raise
        os.close(fd)
        os.replace(self.tmp, self.path)
        if padded:
            self.fd = os.open(self.path, os.O_WRONLY)
            self.flip = len(head.encode())
            self.cursor = len(body)
            self.pad_end = len(body) + reserve

    # ------------------------------------------------------------------ closing

    def close(self) -> None:
        """Wait for the background writer, close the data chunk and rewrite ``solution.xdmf`` without
        padding (collective; idempotent). Raises a failure of the writes still pending.

        If that rewrite fails (e.g. a full disk) the padded file stays: it is valid as it is.
        """
        if self.closed:
            return
        self.closed = True

        def finish() -> None:
            if self._worker is not None:
                self._worker.stop()
            failed = self._worker is not None and self._worker.error is not None
            if self.chunk is not None:
                os.close(self.chunk.fd)
                self.chunk = None
            if self.fd is not None:
                try:
                    self._rewrite(padded=False)
                except OSError:
                    pass
                if self.fd is not None:
                    os.close(self.fd)
                    self.fd = None
            if failed:
                self._raise_pending()

        self._collective(finish)


def describe_oserror(exc: OSError) -> str:
    """``No space left on device (writing results/fields/levels_000100.h5)``: the reason and the file."""
    reason = exc.strerror or str(exc)
    return f"{reason} ({exc.filename})" if exc.filename else reason


def read_series(path: str | Path) -> dict:
    """Read a series back with h5py (independently of the writer): points, cells, times, {field: [values per time]}
    (None at a time that lacks the field: a restart may change ``output.fields``)."""
    import h5py

    path = Path(path)
    root = ET.parse(path).getroot()
    grids = root.find("Domain/Grid").findall("Grid")
    files: dict[str, h5py.File] = {}

    def load(item: ET.Element) -> np.ndarray:
        name, dataset = item.text.strip().split(":", 1)
        if name not in files:
            files[name] = h5py.File(path.parent / name, "r")
        data = files[name][dataset][...]
        dims = tuple(int(d) for d in item.get("Dimensions").split())
        if data.shape != dims:
            raise ValueError(f"{name}:{dataset}: shape {data.shape}, the XML says {dims}")
        return data

    out: dict = {"times": [], "fields": {}}
    try:
        for g in grids:
            if "points" not in out:
                out["points"] = load(g.find("Geometry/DataItem"))
                out["cells"] = load(g.find("Topology/DataItem"))
            i = len(out["times"])
            out["times"].append(float(g.find("Time").get("Value")))
            for att in g.findall("Attribute"):
                values = out["fields"].setdefault(att.get("Name"), [])
                values += [None] * (i - len(values)) + [load(att.find("DataItem"))]
        for values in out["fields"].values():
            values += [None] * (len(out["times"]) - len(values))
    finally:
        for f in files.values():
            f.close()
    return out

