"""``python -m solver paraview`` renders a results directory with ParaView's pvbatch (skipped without ParaView),
and ParaView's three XDMF readers read what solver/io/xdmf.py writes."""

import json
import os
import re
import shutil
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
from conftest import ROOT, read_only

import solver.post.paraview as spv

pytestmark = pytest.mark.serial  # starts its own processes (pvbatch has its own MPI)

RENDER = "import sys; from solver.post.paraview import main; sys.exit(main(sys.argv[1:]))"


@pytest.fixture(scope="module")
def paraview():
    """Skip (with the reason the command itself would give) unless pvbatch runs with its Python modules."""
    if not spv.available():
        pytest.skip("ParaView (pvbatch) is not installed: apt-get install paraview")
    problem = spv.python_problem()
    if problem:
        pytest.skip(problem.removeprefix("error: "))


@pytest.fixture(scope="module")
def results(tmp_path_factory, paraview):
    """A tiny example-1 run: 6 x 6 mesh, times 0, 0.25, ..., 1, with the contact results among the fields."""
    out = tmp_path_factory.mktemp("paraview") / "r"
    fields = '["displacement", "damage", "von_mises", "von_mises_elastic", "contact_pressure", "gap", "penetration"]'
    run = [sys.executable, "-m", "solver", "run", "configs/example1.toml", "--output", str(out), "--no-progress",
           "--set", "mesh.nx=6", "--set", "mesh.ny=6", "--set", "time.k=0.25", "--set", f"output.fields={fields}"]
    res = subprocess.run(run, cwd=ROOT, capture_output=True, text=True, timeout=600)
    assert res.returncode == 0, res.stderr[-2000:]
    return out


def render(*args: str) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, "-c", RENDER, *args], cwd=ROOT, capture_output=True, text=True, timeout=300)


@pytest.mark.slow
def test_paraview_renders_von_mises(results):
    png = results / "pv.png"
    res = render(str(results), "--field", "von_mises", "--output", str(png), "--size", "900", "600")
    assert res.returncode == 0, res.stdout[-2000:] + res.stderr[:3000] + res.stderr[-1000:]
    # ParaView sees the written times and the arrays under their names
    times = re.search(r"time values \(\d+\): \[(.*)\]", res.stdout)
    assert times, res.stdout
    assert [float(t) for t in times.group(1).split(",")] == pytest.approx([0, 0.25, 0.5, 0.75, 1])
    names = set(re.findall(r"(\w+)\[\d+\]", res.stdout))
    assert {"displacement", "damage", "von_mises", "von_mises_elastic", "contact_pressure", "gap", "penetration"} <= names
    import matplotlib.image as mpimg

    img = mpimg.imread(png)
    assert img.shape[0] >= 600 and img.shape[1] >= 900
    assert np.unique(img.reshape(-1, img.shape[-1]), axis=0).shape[0] > 50  # a picture, not a blank


@pytest.mark.slow
@pytest.mark.parametrize("scene", ["configs/example1_3d.toml", "configs/column3d.toml"])
def test_paraview_renders_a_3d_result(tmp_path, paraview, scene):
    """3-D results (issue 32, item 16): the undeformed outline's solid colour failed there ("invalid association
    string 'NONE'" from ColorBy(rep, None)), then an X error at exit."""
    out = tmp_path / "r"
    run = [sys.executable, "-m", "solver", "run", scene, "--output", str(out), "--no-progress", "--set", "time.T=0.1",
           "--set", "time.k=0.05"]
    if "example1_3d" in scene:
        run += ["--set", "mesh.nx=3", "--set", "mesh.ny=3", "--set", "mesh.nz=3"]
    res = subprocess.run(run, cwd=ROOT, capture_output=True, text=True, timeout=600)
    assert res.returncode == 0, res.stderr[-2000:]
    png = tmp_path / "pv.png"
    res = render(str(out), "--output", str(png), "--size", "600", "400")
    assert res.returncode == 0, res.stdout[-2000:] + res.stderr[-2000:]
    assert "invalid association" not in res.stderr and png.stat().st_size > 10_000


def test_the_virtual_display_survives_its_last_client():
    """The private Xvfb does not reset when a client leaves: pvbatch's next connection came during the reset and it
    aborted ("bad X server connection"; scripts/paraview_renders.py: 6 of 24 concurrent renders without -noreset,
    0 of 24 with it). A root-window property set by one client is still there for the next only without a reset."""
    xvfb, xprop = shutil.which("Xvfb"), shutil.which("xprop")
    if xvfb is None or xprop is None:
        pytest.skip("needs Xvfb and xprop (apt-get install xvfb x11-utils)")
    with spv.virtual_display(xvfb) as display:
        subprocess.run([xprop, "-display", display, "-root", "-f", "SOLVER_TEST", "8s", "-set", "SOLVER_TEST", "kept"],
                       check=True, timeout=60)
        res = subprocess.run([xprop, "-display", display, "-root", "SOLVER_TEST"], capture_output=True, text=True,
                             timeout=60)
    assert res.stdout.strip() == 'SOLVER_TEST(STRING) = "kept"', res.stdout + res.stderr


@pytest.mark.slow
def test_paraview_default_output_and_bad_field(results):
    res = render(str(results), "--time", "0.5", "--warp", "1")
    assert res.returncode == 0, res.stdout[-2000:] + res.stderr[-2000:]
    assert (results / "paraview_von_mises_elastic.png").stat().st_size > 10_000
    res = render(str(results), "--field", "nope")
    assert res.returncode == 2 and "--field nope" in res.stderr


def test_paraview_missing_is_one_line(monkeypatch, capsys):
    monkeypatch.setattr(spv.shutil, "which", lambda name: None)
    assert not spv.available()
    assert spv.main([str(ROOT / "results")]) == 2
    assert capsys.readouterr().err.strip() == spv.NOT_INSTALLED


def test_paraview_help_needs_no_paraview(monkeypatch, capsys):
    monkeypatch.setattr(spv.shutil, "which", lambda name: None)
    assert spv.main(["--help"]) == 0
    out = capsys.readouterr()
    assert out.out.startswith("usage:") and "--field" in out.out and out.err == ""


@pytest.fixture(scope="module")
def tiny(tmp_path_factory):
    """A tiny example-1 run (no ParaView needed)."""
    out = tmp_path_factory.mktemp("tiny") / "r"
    run = [sys.executable, "-m", "solver", "run", "configs/example1.toml", "--output", str(out), "--no-progress",
           "--set", "mesh.nx=4", "--set", "mesh.ny=4", "--set", "time.k=0.5"]
    assert subprocess.run(run, cwd=ROOT, capture_output=True).returncode == 0
    return out


def test_paraview_refuses_an_output_it_cannot_write(tiny, tmp_path):
    """Checked before ParaView starts: an --output through a file, and a results folder it cannot write."""
    blocker = tmp_path / "file"
    blocker.write_text("x")
    with pytest.raises(spv.UsageError, match=r"cannot write there \(Not a directory\)"):
        spv.check_results([str(tiny), "--output", str(blocker / "pv.png")])
    with read_only(tiny) as reason, pytest.raises(spv.UsageError) as err:
        spv.check_results([str(tiny), "--field", "damage"])
    assert str(err.value) == f"{tiny} (give --output elsewhere): cannot write there ({reason})"
    assert spv.check_results([str(tiny), "--output", str(tmp_path / "pv.png")]) is None


@pytest.mark.slow
def test_paraview_never_reports_a_file_it_did_not_write(tiny, paraview, tmp_path, monkeypatch, capfd):
    """The script itself (the check above skipped) on a folder it cannot write: VTK only logs "Unable to open
    file"; the script says so in one line, exit 2, and never prints "wrote"."""
    monkeypatch.setattr(spv, "check_results", lambda argv: None)
    ro = tmp_path / "ro"
    ro.mkdir()
    with read_only(ro):
        code = spv.main([str(tiny), "--output", str(ro / "pv.png")])
    out = capfd.readouterr()
    assert code == 2 and "wrote" not in out.out, out.out[-1000:] + out.err[-1000:]
    assert f"error: {ro / 'pv.png'}: ParaView could not write it" in out.err


FAKE_PVBATCH = """#!/bin/sh
# pvbatch as Debian's paraview package installs it without python3-paraview: no 'paraview' module
shift  # --force-offscreen-rendering
exec {python} -c '{code}' "$@"
"""
FAKE_CODE = ('import runpy, sys; sys.modules["paraview"] = None; sys.argv = sys.argv[1:]; '
             'runpy.run_path(sys.argv[0], run_name="__main__")')


def test_pvbatch_without_python_modules_is_one_line(tmp_path):
    """pvbatch present, python3-paraview not: one line saying what to install, exit 2, no retry."""
    fake = tmp_path / "pvbatch"
    fake.write_text(FAKE_PVBATCH.format(python=sys.executable, code=FAKE_CODE))
    fake.chmod(0o755)
    env = dict(os.environ, PATH=f"{tmp_path}{os.pathsep}{os.environ['PATH']}", DISPLAY=":99")
    res = subprocess.run([sys.executable, "-c", RENDER, str(tmp_path)], cwd=ROOT, env=env, capture_output=True,
                         text=True, timeout=120)
    assert res.returncode == 2, res.stderr
    assert res.stderr.strip() == "error: ParaView's Python modules are not installed, which pvbatch needs " \
                                 "(Debian: apt-get install python3-paraview)", res.stderr
    assert spv.python_problem(str(fake)) == res.stderr.strip()


READ_ALL = """
import json, sys
import paraview.simple as pvs
from paraview import servermanager as sm
from vtkmodules.util.numpy_support import vtk_to_numpy
out = {}
for name in ("Xdmf3ReaderS", "Xdmf3ReaderT", "XDMFReader"):
    r = pvs.XDMFReader(FileNames=[sys.argv[1]]) if name == "XDMFReader" else getattr(pvs, name)(FileName=[sys.argv[1]])
    times = [float(t) for t in r.TimestepValues]
    r.UpdatePipeline(times[-1])
    d = sm.Fetch(r)
    while d.IsA("vtkMultiBlockDataSet"):
        d = d.GetBlock(0)
    arrays = {}
    for data in (d.GetPointData(), d.GetCellData()):
        for i in range(data.GetNumberOfArrays()):
            a = data.GetArray(i)
            arrays[a.GetName()] = {"type": a.GetDataTypeAsString(), "values": vtk_to_numpy(a).tolist(),
                                   "components": [a.GetComponentName(c) for c in range(a.GetNumberOfComponents())]}
    info = {k: [r.CellData[k].GetComponentName(c) for c in range(r.CellData[k].GetNumberOfComponents())]
            for k in r.CellData.keys()}
    out[name] = {"times": times, "arrays": arrays, "gui_components": info,
                 "points": vtk_to_numpy(d.GetPoints().GetData()).tolist()}
    pvs.Delete(r)
json.dump(out, open(sys.argv[2], "w"))
"""


@pytest.mark.parametrize("closed", [True, False])
def test_paraview_readers_read_the_series(tmp_path, paraview, closed):
    """All three readers: every time, the values of the last level as written (float64 stays float64); with
    Xdmf3ReaderS/T the stress is a symmetric tensor whose components ParaView names XX ... XZ. Also the
    file listed at a checkpoint, while the writer is still open (closed=False)."""
    from mpi4py import MPI
    sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "io"))  # the series fixture of tests/io/test_xdmf.py
    from test_xdmf import FIELDS, Scene

    scene = Scene(MPI.COMM_SELF, n=3)
    w = scene.series(tmp_path / "r")
    times = [0.0, 1 / 3, 2 / 3, 1.0]
    for t in times:
        last = scene.values(t)
        w.write(t, last)
    w.close() if closed else w.flush()
    script = tmp_path / "read_all.py"
    script.write_text(READ_ALL)
    got = subprocess.run([spv.executable(), str(script), str(tmp_path / "r" / "solution.xdmf"), str(tmp_path / "o.json")],
                         env=spv.environment(), capture_output=True, text=True, timeout=300)
    assert got.returncode == 0, got.stderr[-3000:]
    seen = json.loads((tmp_path / "o.json").read_text())
    from solver.io.xdmf import read_series

    ref = read_series(tmp_path / "r" / "solution.xdmf")  # file order; ParaView keeps it
    for reader, r in seen.items():
        assert r["times"] == pytest.approx(times, rel=0, abs=1e-15), reader
        assert np.array_equal(np.array(r["points"])[:, :2], ref["points"]), reader
        assert set(r["arrays"]) == {f.name for f in FIELDS}, reader
        for f in FIELDS:
            a = r["arrays"][f.name]
            assert a["type"] == "double", (reader, f.name)
            want = ref["fields"][f.name][-1]
            values = np.array(a["values"])
            if reader == "XDMFReader" and f.kind == "Tensor6":  # the legacy reader expands to 9 (XX XY XZ YY YZ ZZ)
                assert values.shape == (len(want), 9), reader
                continue
            assert np.array_equal(values.reshape(want.shape), want), (reader, f.name)
        if reader != "XDMFReader":
            assert r["gui_components"]["stress"] == ["XX", "YY", "ZZ", "XY", "YZ", "XZ"], reader
    # the written values are those in memory at the last level
    assert np.array_equal(ref["fields"]["damage"][-1], last["damage"].ravel()[np.argsort(scene.layout.node_keys)])


def _script():
    """paraview_script.py as a module (its camera helpers need no ParaView)."""
    import importlib.util

    spec = importlib.util.spec_from_file_location("paraview_script_under_test", spv.SCRIPT)
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


@pytest.mark.parametrize("face, normal", [((0.5, 0.5, 0.0), (0, 0, -1)), ((1.0, 0.5, 0.5), (1, 0, 0))])
def test_the_3d_camera_looks_at_the_contact_face_from_outside(face, normal):
    """The camera sits on the outer side of the contact face (45 degrees off its normal), not above z = 1."""
    d, up = _script().view_direction((0, 1, 0, 1, 0, 1), face)
    assert np.dot(d, normal) == pytest.approx(np.sqrt(0.5), rel=1e-2) and np.linalg.norm(d) == pytest.approx(1)
    assert abs(np.dot(np.cross(d, up), np.cross(d, up))) > 0.1  # view-up not along the view


def test_the_contact_face_centre_is_read_from_contact_csv(tmp_path):
    (tmp_path / "contact.csv").write_text("step,t,part,s,x,y,z,gap,u_normal,penetration,pressure\n"
                                          "0,0.0,bottom,0,0,0,0,0,0,0,0\n0,0.0,bottom,1,1,1,0,0,0,0,0\n"
                                          "1,0.5,bottom,0,5,5,5,0,0,0,0\n")
    assert _script().contact_face_centre(str(tmp_path)) == (0.5, 0.5, 0.0)
    assert _script().contact_face_centre(str(tmp_path / "nowhere")) is None


@pytest.mark.slow
def test_a_contact_field_not_written_is_drawn_from_contact_csv(tmp_path, paraview):
    """--field contact_pressure on results without contact.xdmf (written before it existed) whose output.fields
    left it out: the contact nodes coloured from contact.csv (the pressure rises towards x = 1 in Example 1: the
    bar's range is the level's)."""
    out = tmp_path / "r"
    run = [sys.executable, "-m", "solver", "run", "configs/example1.toml", "--output", str(out), "--no-progress",
           "--set", "mesh.nx=6", "--set", "mesh.ny=6", "--set", "time.k=0.5"]
    assert subprocess.run(run, cwd=ROOT, capture_output=True, timeout=600).returncode == 0
    (out / "contact.xdmf").unlink()
    png = tmp_path / "p.png"
    res = render(str(out), "--field", "contact_pressure", "--output", str(png), "--size", "600", "400")
    assert res.returncode == 0, res.stdout[-2000:] + res.stderr[-2000:]
    assert "drawn from contact.csv's 'pressure' column" in res.stdout and png.stat().st_size > 10_000
    res = render(str(out), "--field", "gap", "--time", "0.5", "--output", str(png))
    assert res.returncode == 0, res.stdout[-2000:] + res.stderr[-2000:]


def test_plot_and_paraview_warp_by_the_same_levels():
    """solver plot and solver paraview take the automatic warp from the same written levels (the same factor)."""
    from solver.post.plots import warp_levels

    script = _script()
    for n in (1, 2, 21, 22, 101, 1001):
        assert script.warp_levels(n) == warp_levels(n)
        assert warp_levels(n)[0] == 0 and warp_levels(n)[-1] == n - 1 and len(warp_levels(n)) == min(n, 21)

@pytest.mark.slow
@pytest.mark.parametrize("dim", [2, 3])
def test_paraview_colours_the_contact_boundary_by_pressure(tmp_path, paraview, dim):
    """contact.xdmf (Γ_C as a facet mesh) is opened beside solution.xdmf, and ``--field contact_pressure`` colours Γ_C
    by the pressure over the light-grey body: the picture has the colour map's colours where Γ_C is, and ParaView
    read the contact dataset's arrays and time values."""
    out = tmp_path / "r"
    scene = "configs/example1.toml" if dim == 2 else "configs/example1_3d.toml"
    run = [sys.executable, "-m", "solver", "run", scene, "--output", str(out), "--no-progress", "--set", "time.T=0.2",
           "--set", "time.k=0.1", "--set", "output.fields=['displacement']"]
    run += ["--set", "mesh.nx=8", "--set", "mesh.ny=4"] if dim == 2 else ["--set", "mesh.nx=4", "--set", "mesh.ny=4",
                                                                          "--set", "mesh.nz=4"]
    res = subprocess.run(run, cwd=ROOT, capture_output=True, text=True, timeout=600)
    assert res.returncode == 0, res.stderr[-2000:]
    png = tmp_path / "contact.png"
    res = render(str(out), "--field", "contact_pressure", "--output", str(png), "--size", "600", "400")
    assert res.returncode == 0, res.stdout[-2000:] + res.stderr[-2000:]
    arrays = re.search(r"contact boundary \(contact.xdmf\) point arrays: (.*)", res.stdout)
    assert arrays, res.stdout
    assert {"contact_pressure", "gap", "penetration", "normal_displacement", "displacement"} <= set(
        re.findall(r"(\w+)\[\d+\]", arrays.group(1)))
    assert "field contact_pressure (point data, contact.xdmf)" in res.stdout
    import matplotlib.image as mpimg

    img = mpimg.imread(png)[..., :3]
    above_bar = img[: int(0.88 * img.shape[0])]  # the scalar bar sits in the bottom tenth
    coloured = np.count_nonzero(above_bar.max(axis=2) - above_bar.min(axis=2) > 0.3)
    if dim == 2:  # the light-grey body, and Γ_C a coloured line along its bottom
        grey = np.all(np.abs(img - 0.86) < 0.01, axis=2)
        assert grey.sum() > 0.2 * grey.size
        assert coloured > 50
    else:  # Γ_C's face seen through the see-through body
        assert coloured > 0.1 * img.shape[0] * img.shape[1]
    # without the contact dataset the same field is drawn from contact.csv at the contact nodes
    res = render(str(out), "--field", "contact_pressure", "--no-contact", "--output", str(png))
    assert res.returncode == 0 and "drawn from contact.csv's 'pressure' column" in res.stdout, res.stderr[-2000:]
    res = render(str(out), "--field", "nothing", "--output", str(png))
    assert res.returncode == 2 and "not in the file" in res.stderr and "(contact.xdmf)" in res.stderr
