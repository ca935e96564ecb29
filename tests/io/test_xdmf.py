"""The XDMF time-series writer (solver/io/xdmf.py): read back with meshio and h5py, levels listed only once their
chunk file is closed, the XML replaced whole, killed inside each kind of write, a full disk, restarted, and the
same files from one process and from two."""

from __future__ import annotations

import errno
import os
import signal
import subprocess
import sys
import xml.etree.ElementTree as ET
from pathlib import Path

import faults
import numpy as np
import pytest
from conftest import ROOT, mpi_env
from mpi4py import MPI

import solver.io.xdmf as sx
from solver.io.xdmf import FieldSpec, SeriesError, XDMFSeries, read_series

FIELDS = [FieldSpec("displacement", "Node", "Vector"), FieldSpec("damage", "Node", "Scalar"),
          FieldSpec("stress", "Cell", "Tensor6"), FieldSpec("von_mises", "Cell", "Scalar")]


def exact(t: float, points: np.ndarray, cells: np.ndarray) -> dict[str, np.ndarray]:
    """The values the scene below writes at time t, computed from the file's own points and cells."""
    x, y = points[:, 0], points[:, 1]
    mid = points[cells].mean(axis=1)
    cx, cy = mid[:, 0], mid[:, 1]
    zero = np.zeros_like(cx)
    return {
        "displacement": np.stack([x * t, y + t, np.zeros_like(x)], axis=1),
        "damage": 1.0 - x * y * t,
        "stress": np.stack([cx + t, 2 * cy + t, zero, cx * cy - t, zero, zero], axis=1),  # XX YY ZZ XY YZ XZ
        "von_mises": cx + 10 * cy + t,
    }


class Scene:
    """A unit square with one field of each kind, set to known functions of (x, t)."""

    def __init__(self, comm: MPI.Comm, n: int = 6) -> None:
        from dolfinx import fem, mesh

        self.mesh = mesh.create_unit_square(comm, n, n)
        self.u = fem.Function(fem.VectorFunctionSpace(self.mesh, ("CG", 1)))
        self.z = fem.Function(fem.FunctionSpace(self.mesh, ("CG", 1)))
        self.s = fem.Function(fem.TensorFunctionSpace(self.mesh, ("DG", 0)))
        self.v = fem.Function(fem.FunctionSpace(self.mesh, ("DG", 0)))
        self.layout = sx.dolfinx_layout(self.mesh)
        self.rows = sx.DolfinxRows(self.mesh)

    def values(self, t: float) -> dict[str, np.ndarray]:
        self.u.interpolate(lambda x: np.stack([x[0] * t, x[1] + t]))
        self.z.interpolate(lambda x: 1.0 - x[0] * x[1] * t)
        self.s.interpolate(lambda x: np.stack([x[0] + t, x[0] * x[1] - t, x[0] * x[1] - t, 2 * x[1] + t]))
        self.v.interpolate(lambda x: x[0] + 10 * x[1] + t)
        r = self.rows
        return {"displacement": sx.vector3(r.rows(self.u)), "damage": r.rows(self.z),
                "stress": sx.tensor6(r.rows(self.s), 2), "von_mises": r.rows(self.v)}

    def series(self, directory: Path, **kw) -> XDMFSeries:
        return XDMFSeries(directory, self.layout, FIELDS, **kw)


def check_values(res: dict, times: list[float], atol: float = 1e-13, rtol: float = 0.0) -> None:
    """Times as given; every field at every time equal to :func:`exact` (rtol: the rounding of the file's precision)."""
    assert res["times"] == pytest.approx(times, abs=1e-15) and len(res["times"]) == len(times)
    for i, t in enumerate(res["times"]):
        want = exact(t, res["points"], res["cells"])
        for name, values in res["fields"].items():
            assert np.allclose(values[i].reshape(want[name].shape), want[name], rtol=rtol, atol=atol), (name, t)


def meshio_read(path: Path) -> dict:
    """The series as meshio's TimeSeriesReader sees it, in read_series' shape."""
    import meshio

    out: dict = {"times": [], "fields": {}}
    with meshio.xdmf.TimeSeriesReader(str(path)) as reader:
        out["points"], cells = reader.read_points_cells()
        out["cells"] = cells[0].data
        for k in range(reader.num_steps):
            t, pd, cd = reader.read_data(k)
            out["times"].append(t)
            for name, v in [*pd.items(), *((n, c[0]) for n, c in cd.items())]:
                out["fields"].setdefault(name, []).append(v)
    return out


@pytest.mark.parametrize("precision", ["double", "single"])
def test_series_reads_back_in_meshio(comm, shared_tmp, precision):
    """Serial and on 2 ranks: every time, every field, every value; NumberType and Precision on every DataItem."""
    scene = Scene(comm)
    times = [0.0, 0.25, 0.5, 0.75, 1.0]
    w = scene.series(shared_tmp, precision=precision)
    for t in times:
        w.write(t, scene.values(t))
    w.close()
    if comm.rank == 0:
        res = meshio_read(shared_tmp / "solution.xdmf")
        assert res["points"].shape == (49, 2) and res["cells"].shape == (72, 3)
        dtype = np.float64 if precision == "double" else np.float32
        assert all(v.dtype == dtype for vs in res["fields"].values() for v in vs)
        check_values(res, times, rtol=0.0 if precision == "double" else 2.0**-24)  # single: rounded to float32
        items = list(ET.parse(shared_tmp / "solution.xdmf").getroot().iter("DataItem"))
        assert len(items) == len(times) * (2 + len(FIELDS))
        import h5py

        for item in items:
            name, dataset = item.text.strip().split(":")
            with h5py.File(shared_tmp / name, "r") as h5:
                dt = h5[dataset].dtype
            assert (item.get("NumberType"), item.get("Precision")) == ({"f": "Float", "i": "Int"}[dt.kind], str(dt.itemsize))
        # no second XDMF file, nothing left from the writer's temporaries
        assert sorted(p.name for p in shared_tmp.rglob("*") if p.is_file() and p.suffix != ".h5") == ["solution.xdmf"]


def test_tensor6_order_in_3d(comm, shared_tmp):
    from dolfinx import fem, mesh

    m = mesh.create_unit_cube(comm, 2, 2, 2)
    s = fem.Function(fem.TensorFunctionSpace(m, ("DG", 0)))
    full = np.array([[1.0, 4.0, 6.0], [4.0, 2.0, 5.0], [6.0, 5.0, 3.0]])
    s.interpolate(lambda x: np.tile(full.reshape(9, 1), (1, x.shape[1])))
    rows = sx.DolfinxRows(m)
    w = XDMFSeries(shared_tmp, sx.dolfinx_layout(m), [FieldSpec("stress", "Cell", "Tensor6")])
    w.write(0.0, {"stress": sx.tensor6(rows.rows(s), 3)})
    w.close()
    if comm.rank == 0:
        res = read_series(shared_tmp / "solution.xdmf")
        assert res["points"].shape == (27, 3) and res["cells"].shape == (48, 4)
        assert np.array_equal(res["fields"]["stress"][0], np.tile([1.0, 2.0, 3.0, 4.0, 5.0, 6.0], (48, 1)))  # XX YY ZZ XY YZ XZ


def _listed(path: Path) -> list[float]:
    if not path.exists():
        return []
    return [float(g.find("Time").get("Value")) for g in ET.parse(path).getroot().find("Domain/Grid").findall("Grid")]


@pytest.mark.serial
def test_levels_are_listed_once_their_chunk_is_closed(tmp_path, monkeypatch):
    """A level is listed when its chunk file is closed (full, flush, close), never before; the XML is then replaced
    whole (a new inode), and between those moments it does not change. Every listed file opens read-only."""
    import h5py

    monkeypatch.setattr(sx, "MAX_LEVELS_PER_CHUNK", 3)
    scene = Scene(MPI.COMM_SELF, n=2)
    w = scene.series(tmp_path)
    path = tmp_path / "solution.xdmf"
    times = [0.5 * i for i in range(8)]
    seen = []
    for i, t in enumerate(times):
        w.write(t, scene.values(t))
        if i == 4:
            w.flush()  # a checkpoint: levels 3 and 4 listed with their chunk
        state = (_listed(path), path.stat().st_ino if path.exists() else None, path.read_bytes() if path.exists() else b"")
        seen.append(state)
        want = {0: 0, 1: 0, 2: 3, 3: 3, 4: 5, 5: 5, 6: 5, 7: 8}[i]  # chunks 0-2, 3-4 (flushed), 5-7 (full)
        assert state[0] == times[:want], i
        if i and want == len(seen[i - 1][0]):
            assert state[1:] == seen[i - 1][1:], i  # nothing listed: the file is untouched
        elif i and seen[i - 1][1] is not None:
            assert state[1] != seen[i - 1][1], i  # listed: a new file renamed over the old one
        for item in (ET.parse(path).getroot().iter("DataItem") if path.exists() else []):
            name, dataset = item.text.strip().split(":")
            with h5py.File(tmp_path / name, "r") as h5:  # closed by the writer: HDF5's lock lets a reader in
                assert h5[dataset].shape[0] > 0
    assert sorted(p.name for p in (tmp_path / "fields").iterdir()) == [
        "levels_000000.h5", "levels_000003.h5", "levels_000005.h5", "mesh.h5"]
    w.close()
    check_values(meshio_read(path), times)
    assert sorted(p.name for p in tmp_path.iterdir()) == ["fields", "solution.xdmf"]  # no temporary left


@pytest.mark.serial
def test_chunks_keep_their_size_and_the_xml_is_replaced_once_per_chunk(tmp_path, monkeypatch):
    monkeypatch.setattr(sx, "MAX_LEVELS_PER_CHUNK", 7)
    scene = Scene(MPI.COMM_SELF, n=2)
    w = scene.series(tmp_path)
    times = [0.1 * i for i in range(30)]
    replaced, inode = 0, None
    for t in times:
        w.write(t, scene.values(t))
        now = (tmp_path / "solution.xdmf").stat().st_ino if (tmp_path / "solution.xdmf").exists() else None
        replaced, inode = replaced + (now != inode), now
    assert replaced == 4 and len(read_series(tmp_path / "solution.xdmf")["times"]) == 28  # once per full chunk
    w.close()
    check_values(meshio_read(tmp_path / "solution.xdmf"), times)
    assert sorted(p.name for p in (tmp_path / "fields").iterdir()) == [
        "levels_000000.h5", "levels_000007.h5", "levels_000014.h5", "levels_000021.h5", "levels_000028.h5", "mesh.h5"]


@pytest.mark.serial
@pytest.mark.parametrize("stage,at,listed", [("data", 6, 5), ("data", 3, 2), ("close", 2, 3), ("file", 3, 3),
                                             ("file", 4, 3)])
def test_full_disk_is_one_line_with_the_level_and_keeps_what_is_complete(tmp_path, monkeypatch, stage, at, listed):
    """ENOSPC inside a level's data (after its first field), after a chunk's file is written, or half-way through
    a chunk file (file 3) or the XML's temporary (file 4): SeriesError with one line and the failed level's t; the
    complete levels are listed (those of the open chunk too, when its file can still be written), the XML is never
    left half written, a chunk file not listed is removed, no more levels are taken, close() finishes quietly."""
    monkeypatch.setattr(sx, "MAX_LEVELS_PER_CHUNK", 3)
    for name in ("_write_dataset", "_close_chunk", "_write_file"):
        monkeypatch.setattr(sx, name, getattr(sx, name))  # restored after the test: faults.install replaces them
    monkeypatch.setattr(sx._Chunk, "add", sx._Chunk.add)
    faults.install(f"enospc:{stage}:{at}")
    scene = Scene(MPI.COMM_SELF, n=2)
    w = scene.series(tmp_path)
    times = [0.5 * i for i in range(8)]
    with pytest.raises(SeriesError) as failed:
        for t in times:
            w.write(t, scene.values(t))
    chunk = {"data": None, "close": at, "file": (at + 1) // 2}[stage]
    failed_t = times[at - 1] if chunk is None else times[3 * chunk - 1]  # the level that filled the chunk
    assert failed.value.t == failed_t and "\n" not in str(failed.value)
    assert str(failed.value).startswith("No space left on device"), str(failed.value)
    with pytest.raises(SeriesError, match="No space left on device"):
        w.write(99.0, scene.values(99.0))
    w.close()
    check_values(read_series(tmp_path / "solution.xdmf"), times[:listed])
    check_values(meshio_read(tmp_path / "solution.xdmf"), times[:listed])
    assert not (tmp_path / ".solution.xdmf.tmp").exists()
    referenced = {i.text.split(":")[0] for i in ET.parse(tmp_path / "solution.xdmf").getroot().iter("DataItem")}
    assert {f"fields/{p.name}" for p in (tmp_path / "fields").iterdir()} == referenced


def test_hdf5_errors_are_described_in_one_line():
    """h5py's OSError carries HDF5's multi-line message: the reason comes from its errno, the file from its text."""
    exc = OSError(errno.ENOSPC, "Can't write data (file write failed: time = Wed Nov 25 00:05:08 2026\n, "
                                "filename = 'out/fields/levels_000100.h5', file descriptor = 3, errno = 28, "
                                "error message = 'No space left on device', buf = 0x39c82d0, total write size = 82048)")
    assert sx.describe_oserror(exc) == "No space left on device (out/fields/levels_000100.h5)"
    assert sx.describe_oserror(OSError(errno.EACCES, "Permission denied", "x.csv")) == "Permission denied (x.csv)"


def _crash(w: XDMFSeries) -> None:
    """Drop a writer as a killed process would: the open chunk's file left unlisted, nothing tidied."""
    if w._settler is not None:
        w._settler.stop()
    if w.chunk is not None:
        w.chunk.drop()  # in memory: lost, as in a killed process
    w.closed = True


@pytest.mark.parametrize("closed", [True, False])
def test_restart_keeps_levels_up_to_t_and_continues(comm, shared_tmp, monkeypatch, closed):
    monkeypatch.setattr(sx, "MAX_LEVELS_PER_CHUNK", 3)
    scene = Scene(comm)
    first = [0.1 * i for i in range(9)]
    w = scene.series(shared_tmp)
    for t in first:
        w.write(t, scene.values(t + 100.0))  # the first run's values: t + 100
        if abs(t - 0.4) < 1e-12:
            w.flush()  # a checkpoint: chunks 0-2 (full), 3-4 (flushed), 5-7 (full) listed; 8 not, when crashed
    w.close() if closed else _crash(w)
    w = scene.series(shared_tmp, keep_until=0.30000000000000004)
    assert w.times == pytest.approx(first[:4]) if comm.rank == 0 else w.times == []
    second = [0.1 * i for i in range(4, 10)]
    for t in second:
        w.write(t, scene.values(t))
    w.close()
    if comm.rank == 0:
        res = read_series(shared_tmp / "solution.xdmf")
        assert res["times"] == pytest.approx(first[:4] + second) and len(res["times"]) == 10
        kept = {k: vs[:4] for k, vs in res["fields"].items()}
        check_values(dict(res, times=[t + 100.0 for t in res["times"][:4]], fields=kept),
                     [t + 100.0 for t in first[:4]], atol=1e-11)  # the kept levels hold the first run's values
        check_values(dict(res, times=res["times"][4:], fields={k: vs[4:] for k, vs in res["fields"].items()}), second)
        seen = meshio_read(shared_tmp / "solution.xdmf")
        assert seen["times"] == res["times"]
        assert all(np.array_equal(x, y) for k in res["fields"] for x, y in zip(seen["fields"][k], res["fields"][k]))
        referenced = {i.text.split(":")[0] for i in ET.parse(shared_tmp / "solution.xdmf").getroot().iter("DataItem")}
        on_disk = {f"fields/{p.name}" for p in (shared_tmp / "fields").iterdir()}
        assert on_disk == referenced  # no chunk left that no level refers to


def test_restart_refuses_another_mesh(comm, shared_tmp):
    a = Scene(comm, n=6)
    w = a.series(shared_tmp)
    w.write(0.0, a.values(0.0))
    w.close()
    b = Scene(comm, n=5)
    with pytest.raises(SeriesError, match="holds another mesh"):
        b.series(shared_tmp, keep_until=0.0)


def test_bad_arguments(comm, tmp_path):
    scene = Scene(MPI.COMM_SELF, n=2)
    with pytest.raises(ValueError, match="precision 'half'"):
        scene.series(tmp_path, precision="half")
    with pytest.raises(ValueError, match="no name twice"):
        XDMFSeries(tmp_path, scene.layout, [FIELDS[0], FIELDS[0]])
    with pytest.raises(ValueError, match="kind 'Tensor'"):
        FieldSpec("stress", "Cell", "Tensor")
    with pytest.raises(ValueError, match="letters, digits"):
        FieldSpec("von mises", "Cell", "Scalar")


def _example2_mesh(comm: MPI.Comm):
    """Example 2's gmsh mesh, read on rank 0 and distributed (as solver/mesh/geometry.py does)."""
    import gmsh
    from dolfinx.io import gmshio

    if comm.rank == 0:
        gmsh.initialize()
        gmsh.option.setNumber("General.Terminal", 0)
        gmsh.merge(str(ROOT / "meshes" / "example2.msh"))
    try:
        return gmshio.model_to_mesh(gmsh.model, comm, 0, gdim=2)[0]
    finally:
        if comm.rank == 0:
            gmsh.finalize()


@pytest.mark.skipif(MPI.COMM_WORLD.size == 1, reason="compares a 2-rank writer with a one-process one")
def test_one_process_and_two_ranks_write_the_same_files(comm, shared_tmp):
    """The same rows in the same order: mesh and values identical, the XML byte for byte."""
    cases = {"square": lambda c: Scene(c, n=7).mesh, "gmsh": _example2_mesh}
    for name, make in cases.items():
        for tag, c in (("par", comm), ("ser", MPI.COMM_SELF if comm.rank == 0 else None)):
            if c is None:
                continue
            lay = sx.dolfinx_layout(make(c))
            # values made from what each rank owns (not through dolfinx's interpolation, whose evaluation
            # points differ in the last bit between partitions)
            x, y = lay.points[:, 0], lay.points[:, 1]
            u = sx.vector3(np.stack([3 * x * y, x - y * y], axis=1))
            g = 0.5 * lay.cell_keys + 1.0
            w = XDMFSeries(shared_tmp / name / tag, lay, [FieldSpec("u", "Node", "Vector"), FieldSpec("g", "Cell", "Scalar")])
            for t in (0.0, 1.0):
                w.write(t, {"u": u * (1 + t), "g": g + t})
            w.close()
        comm.barrier()
        problems = []
        if comm.rank == 0:
            a, b = shared_tmp / name / "ser", shared_tmp / name / "par"
            if (a / "solution.xdmf").read_bytes() != (b / "solution.xdmf").read_bytes():
                problems.append("xml")
            ra, rb = read_series(a / "solution.xdmf"), read_series(b / "solution.xdmf")
            problems += [k for k in ("points", "cells") if not np.array_equal(ra[k], rb[k])]
            problems += [f"{key}: {np.abs(x - y).max():.1e}" for key in ra["fields"]
                         for x, y in zip(ra["fields"][key], rb["fields"][key]) if not np.array_equal(x, y)]
        assert comm.bcast(problems, root=0) == [], name  # on every rank: a failure must not leave one rank waiting


# ---------------------------------------------------------------------------- killed inside a write

KILLED = """
import sys
import numpy as np
from mpi4py import MPI
sys.path[:0] = [{tests!r}, {tests!r} + "/.."]  # test_xdmf, and the conftest it imports
import solver.io.xdmf as sx
from test_xdmf import Scene
sx.MAX_LEVELS_PER_CHUNK = 4
out, keep = sys.argv[1], (float(sys.argv[2]) if len(sys.argv) > 2 else None)
times = [0.1 * i for i in range(12)]
if keep is not None:
    times = [t for t in times if t > keep + 1e-12]
scene = Scene(MPI.COMM_WORLD)
w = scene.series(out, keep_until=keep)
for t in times:
    w.write(t, scene.values(t))
w.close()
"""


def _run(script: Path, args: list[str], nproc: int, env: dict, fault: str | None = None) -> subprocess.CompletedProcess:
    cmd = [sys.executable, str(script), *args] if fault is None else faults.command(fault, [str(script), *args])
    if nproc > 1:
        cmd = ["mpirun", "-n", str(nproc), "--oversubscribe", *cmd]
    return subprocess.run(cmd, cwd=ROOT, env=env, capture_output=True, text=True, timeout=300)


@pytest.mark.serial
@pytest.mark.parametrize("stage,at,listed,nproc", [
    ("data", 6, 4, 1),  # inside the 6th level's data (chunk 4-7 open): levels 0-3 listed
    ("data", 3, 0, 1),  # inside the 3rd level's data: nothing listed yet, no solution.xdmf
    ("close", 2, 4, 1),  # chunk 4-7 written, not yet listed
    ("file", 3, 4, 1),  # chunk 4-7 half written
    ("file", 4, 4, 1),  # the XML listing levels 0-7 half written to its temporary, not renamed
    ("data", 10, 8, 2),  # 2 ranks, rank 0 killed inside a data write
])
def test_killed_inside_a_write_then_restarted(tmp_path, stage, at, listed, nproc):
    script = tmp_path / "killed.py"
    script.write_text(KILLED.format(tests=str(Path(__file__).resolve().parent)))
    out = tmp_path / "out"
    env = dict(mpi_env(), PYTHONPATH=os.pathsep.join([str(ROOT), os.environ.get("PYTHONPATH", "")]))
    res = _run(script, [str(out)], nproc, env, fault=f"kill:{stage}:{at}")
    if nproc == 1:
        assert res.returncode == -signal.SIGKILL, res.stderr[-2000:]
    else:
        assert res.returncode != 0 and "signal 9" in res.stdout + res.stderr, res.stdout[-2000:] + res.stderr[-2000:]
    xdmf = out / "solution.xdmf"
    times = [0.1 * i for i in range(listed)]
    if listed:
        check_values(read_series(xdmf), times)  # only complete levels, each with its right values
        check_values(meshio_read(xdmf), times)
    else:
        assert not xdmf.exists()
    res = _run(script, [str(out), repr(times[-1])] if listed else [str(out)], nproc, env)
    assert res.returncode == 0, res.stderr[-2000:]
    check_values(read_series(xdmf), [0.1 * i for i in range(12)])
    check_values(meshio_read(xdmf), [0.1 * i for i in range(12)])
    referenced = {i.text.split(":")[0] for i in ET.parse(xdmf).getroot().iter("DataItem")}
    assert {f"fields/{p.name}" for p in (out / "fields").iterdir()} == referenced  # the unlisted chunk removed
    assert sorted(p.name for p in out.iterdir()) == ["fields", "solution.xdmf"]  # and the temporary XML


def test_vector3_of_no_rows():
    """A rank that owns none of a series' nodes (Γ_C's in contact.xdmf, on 2 ranks of a 4 x 4 mesh) writes zero rows:
    they reshape to (0, 3) instead of failing on that rank alone (the others then waited for it)."""
    from solver.io.xdmf import vector3

    assert vector3(np.zeros((0, 2))).shape == (0, 3)
    assert vector3(np.zeros((0, 3))).shape == (0, 3)
    assert np.array_equal(vector3(np.ones((2, 2))), [[1, 1, 0], [1, 1, 0]])


def test_vector3_kept_array_equals_vector3_level_after_level():
    """Vector3 (the writers' displacement, padded into an array kept between levels) gives vector3's values at every
    call: 1 and 2 components, a new row count or type, zero rows, and 3 components passed through."""
    rng = np.random.default_rng(5)
    pad = sx.Vector3()
    for rows in [rng.standard_normal((4, 2)) for _ in range(3)] + [rng.standard_normal((4, 1)), rng.standard_normal(4),
                                                                  rng.standard_normal((6, 2)),
                                                                  rng.standard_normal((6, 2)).astype(np.float32),
                                                                  np.zeros((0, 2)), rng.standard_normal((3, 3))]:
        got = pad(rows)
        want = sx.vector3(rows)
        assert got.dtype == want.dtype and np.array_equal(got, want)
    first = pad(np.ones((2, 2)))
    assert pad(np.full((2, 2), 2.0)) is first and np.array_equal(first, [[2, 2, 0], [2, 2, 0]])  # the same array


@pytest.mark.serial
def test_large_levels_written_field_by_field_give_the_same_files(tmp_path, monkeypatch):
    """A level's part of a chunk file is assembled in memory up to STAGE_BYTES and written at once, a larger one field
    by field: both ways, and chunks closed full, by a flush and at the end, give the same files, byte for byte."""
    monkeypatch.setattr(sx, "MAX_LEVELS_PER_CHUNK", 3)
    scene = Scene(MPI.COMM_SELF, n=3)
    times = [0.25 * i for i in range(8)]
    for stage, name in ((sx.STAGE_BYTES, "staged"), (0, "by_field")):
        monkeypatch.setattr(sx, "STAGE_BYTES", stage)
        w = scene.series(tmp_path / name)
        for i, t in enumerate(times):
            w.write(t, scene.values(t))
            if i == 4:
                w.flush()  # chunk 3-4 closed early: written again as a 2-level file
        w.close()
        check_values(read_series(tmp_path / name / "solution.xdmf"), times)
    files = sorted(p.name for p in (tmp_path / "staged" / "fields").iterdir())
    assert files == ["levels_000000.h5", "levels_000003.h5", "levels_000005.h5", "mesh.h5"]
    assert files == sorted(p.name for p in (tmp_path / "by_field" / "fields").iterdir())
    for f in files:
        assert (tmp_path / "staged" / "fields" / f).read_bytes() == (tmp_path / "by_field" / "fields" / f).read_bytes()


@pytest.mark.serial
def test_a_chunk_closed_early_whose_small_levels_share_parts_is_written_again_whole(tmp_path, monkeypatch):
    """Small levels: HDF5 groups several levels' datasets in one part of the file, so a chunk closed before it is full
    has fewer parts than levels; the file of its levels is still complete (every level reads back)."""
    monkeypatch.setattr(sx, "MAX_LEVELS_PER_CHUNK", 40)
    scene = Scene(MPI.COMM_SELF, n=2)
    times = [0.1 * i for i in range(25)]
    w = scene.series(tmp_path)
    for t in times:
        w.write(t, scene.values(t))
    w.close()
    assert len(w._template(25).cut) - 1 < 25  # the case: fewer parts than levels
    check_values(read_series(tmp_path / "solution.xdmf"), times)
    check_values(meshio_read(tmp_path / "solution.xdmf"), times)


@pytest.mark.serial
def test_a_chunk_sized_to_the_levels_left_is_written_once_and_gives_the_same_files(tmp_path, monkeypatch):
    """``write(..., left)``: a chunk opened with ``left`` levels to go before the next flush or close holds that many,
    so that it is full when closed and never written again as a file of fewer levels; its files are byte for byte
    those of the chunks closed early and written again."""
    monkeypatch.setattr(sx, "MAX_LEVELS_PER_CHUNK", 3)
    scene = Scene(MPI.COMM_SELF, n=3)
    times = [0.25 * i for i in range(9)]
    flush_at, rewrites = 4, []
    for name in ("closed_early", "sized"):
        if name == "sized":
            monkeypatch.setattr(sx._Chunk, "_rewrite", lambda self, n: rewrites.append(n))
        w = scene.series(tmp_path / name)
        for i, t in enumerate(times):
            stop = flush_at if i <= flush_at else len(times) - 1
            w.write(t, scene.values(t), left=stop - i + 1 if name == "sized" else None)
            if i == flush_at:
                w.flush()
        w.close()
        check_values(read_series(tmp_path / name / "solution.xdmf"), times)
    assert rewrites == []  # chunks 3-4 (flushed) and 8 (closed) were full when closed
    files = sorted(p.name for p in (tmp_path / "sized" / "fields").iterdir())
    assert files == ["levels_000000.h5", "levels_000003.h5", "levels_000005.h5", "levels_000008.h5", "mesh.h5"]
    for f in files:
        assert (tmp_path / "sized" / "fields" / f).read_bytes() == (tmp_path / "closed_early" / "fields" / f).read_bytes()
    assert (tmp_path / "sized" / "solution.xdmf").read_bytes() == (tmp_path / "closed_early" / "solution.xdmf").read_bytes()
