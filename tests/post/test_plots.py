"""``python -m solver plot`` renders the paper-style pictures from a results directory."""

import os
import subprocess
import sys

import numpy as np
import pytest
from conftest import ROOT, read_only

pytestmark = pytest.mark.serial  # starts its own processes

HIDE = "import sys; sys.modules['{m}'] = None; from solver.cli import main; sys.exit(main({argv!r}))"


@pytest.mark.parametrize("module", ["pyvista", "matplotlib"])
def test_plot_without_the_plotting_extra_is_one_line(module, tmp_path):
    """A slim installation (make install PLOTS=0) has no plotting stack: plot says what is missing, exit 2."""
    res = subprocess.run([sys.executable, "-c", HIDE.format(m=module, argv=["plot", str(tmp_path)])], cwd=ROOT,
                         capture_output=True, text=True)
    assert res.returncode == 2 and res.stderr.count("\n") == 1 and "Traceback" not in res.stderr
    assert res.stderr.startswith("error: plot needs ") and module in res.stderr and "PLOTS=1" in res.stderr


def test_charts_are_skipped_without_matplotlib(capsys, monkeypatch):
    from solver.post.charts import pyplot

    monkeypatch.setitem(sys.modules, "matplotlib", None)
    assert pyplot("the chart") is None
    assert "the chart skipped: matplotlib is not installed" in capsys.readouterr().out


@pytest.mark.slow
def test_plot_writes_pictures(tmp_path):
    pytest.importorskip("pyvista", reason="the plotting extra is not installed (make install PLOTS=0)")
    env = dict(os.environ)
    out = tmp_path / "r"
    run = [sys.executable, "-m", "solver", "run", "configs/example1.toml", "--output", str(out), "--no-progress",
           "--set", "mesh.nx=6", "--set", "mesh.ny=6", "--set", "time.k=0.25"]
    assert subprocess.run(run, cwd=ROOT, env=env, capture_output=True).returncode == 0
    res = subprocess.run([sys.executable, "-m", "solver", "plot", str(out)], cwd=ROOT, env=env,
                         capture_output=True, text=True, timeout=300)
    assert res.returncode == 0, res.stderr[-2000:]
    names = {"von_mises_elastic_initial.png", "von_mises_elastic_final.png", "von_mises_initial.png",
             "von_mises_final.png", "damage_final.png", "timeseries.png", "contact_bottom.png"}
    assert names <= {p.name for p in out.iterdir()}
    import matplotlib.image as mpimg

    for name in names:
        img = mpimg.imread(out / name)
        assert img.shape[0] > 300 and img.shape[1] > 600
        assert np.unique(img.reshape(-1, img.shape[-1]), axis=0).shape[0] > 50  # a picture, not a blank


def test_plot_refuses_a_non_results_directory(tmp_path):
    pytest.importorskip("pyvista", reason="the plotting extra is not installed (make install PLOTS=0)")
    res = subprocess.run([sys.executable, "-m", "solver", "plot", str(tmp_path)], cwd=ROOT, capture_output=True,
                         text=True)
    assert res.returncode != 0 and "no solution.xdmf" in res.stderr


def test_plot_draws_3d_results(tmp_path):
    pytest.importorskip("pyvista", reason="the plotting extra is not installed (make install PLOTS=0)")
    out = tmp_path / "r"
    run = [sys.executable, "-m", "solver", "run", "configs/example1_3d.toml", "--output", str(out), "--no-progress",
           "--set", "mesh.nx=2", "--set", "mesh.ny=2", "--set", "mesh.nz=2", "--set", "time.k=0.5"]
    assert subprocess.run(run, cwd=ROOT, capture_output=True).returncode == 0
    res = subprocess.run([sys.executable, "-m", "solver", "plot", str(out)], cwd=ROOT, capture_output=True, text=True)
    assert res.returncode == 0, res.stderr[-2000:]
    assert (out / "von_mises_final.png").stat().st_size > 10_000


def test_contact_profiles_draw_the_pressure_along_each_part(tmp_path):
    """p(s) per contact part at up to six written levels, from what read_profile returns."""
    pytest.importorskip("matplotlib")
    from solver.post.plots import contact_profiles

    s = np.linspace(0.0, 1.0, 21)
    profile = {}
    for step in range(10):
        pen = 1e-3 * (0.3 + 0.05 * step - s)
        profile[(step, "bottom")] = {"t": np.full(21, 0.1 * step), "s": s, "gap": 0 * s, "u_normal": pen,
                                     "penetration": pen, "pressure": np.maximum(pen, 0) * 1e4}
    made = contact_profiles(profile, tmp_path)
    assert [p.name for p in made] == ["contact_bottom.png"]
    import matplotlib.image as mpimg

    img = mpimg.imread(made[0])
    assert img.shape[0] > 300 and np.unique(img.reshape(-1, img.shape[-1]), axis=0).shape[0] > 50


@pytest.mark.slow
def test_plot_refuses_an_output_it_cannot_write(tmp_path):
    """One line and exit 2 before drawing: an --output through a file, and a results folder it cannot write (made
    by another user: the Dockerfile's plot example without --user)."""
    pytest.importorskip("pyvista", reason="the plotting extra is not installed (make install PLOTS=0)")
    out = tmp_path / "r"
    run = [sys.executable, "-m", "solver", "run", "configs/example1.toml", "--output", str(out), "--no-progress",
           "--set", "mesh.nx=4", "--set", "mesh.ny=4", "--set", "time.k=0.5"]
    assert subprocess.run(run, cwd=ROOT, capture_output=True).returncode == 0
    plot = [sys.executable, "-m", "solver", "plot", str(out)]
    blocker = tmp_path / "file"
    blocker.write_text("x")
    res = subprocess.run([*plot, "--output", str(blocker / "o")], cwd=ROOT, capture_output=True, text=True)
    assert res.returncode == 2 and res.stdout == "", res.stderr
    assert res.stderr == f"error: --output {blocker / 'o'}: cannot write there (Not a directory)\n"
    before = sorted(p.name for p in out.iterdir())
    with read_only(out) as reason:
        res = subprocess.run(plot, cwd=ROOT, capture_output=True, text=True)
    assert res.returncode == 2 and res.stdout == "", res.stderr
    assert res.stderr == f"error: {out} (give --output elsewhere): cannot write there ({reason})\n"
    assert sorted(p.name for p in out.iterdir()) == before


def test_plot_outside_the_venv_names_the_python_to_use(monkeypatch, capsys, tmp_path):
    """Debian's python3 in the repository root imports the source folder but not the venv's plotting stack: the
    message names the Python to use, not a slim image."""
    from solver.cli import main

    monkeypatch.setitem(sys.modules, "pyvista", None)
    monkeypatch.setattr(sys, "base_prefix", sys.prefix)
    assert main(["plot", str(tmp_path)]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and f"this Python ({sys.executable}) does not see" in err
    assert ".venv/bin/python -m solver plot" in err and "slim" not in err


def _square(solid: bool) -> dict:
    """A unit square (triangles) or cube (tetrahedra) with the field x at the nodes and no displacement."""
    import pyvista as pv

    n = 9
    if solid:
        grid = pv.ImageData(dimensions=(n, n, n), spacing=(1 / (n - 1),) * 3).triangulate().cast_to_unstructured_grid()
        pts, cells = np.asarray(grid.points), grid.cells.reshape(-1, 5)[:, 1:]
    else:
        g = np.linspace(0.0, 1.0, n)
        pts = np.array([(x, y) for y in g for x in g])
        cells = np.array([c for j in range(n - 1) for i in range(n - 1) for c in
                          (((j * n + i), (j * n + i + 1), ((j + 1) * n + i + 1)),
                           ((j * n + i), ((j + 1) * n + i + 1), ((j + 1) * n + i)))])
    return {"geometry": pts, "topology": cells, "times": [0.0], "fields": {"x": {0.0: pts[:, 0].copy()}}}


@pytest.mark.parametrize("solid", [False, True])
def test_a_pixel_has_the_colour_bar_colour_of_its_value(solid, tmp_path):
    """Flat colours: every pixel of the body is a colour of the colour map (lit faces would be darker), and in 2-D
    the value read back through the bar grows from left to right as the drawn field x does."""
    pytest.importorskip("pyvista", reason="the plotting extra is not installed (make install PLOTS=0)")
    import matplotlib
    import matplotlib.image as mpimg

    res = _square(solid)
    # rendered in a process of its own: VTK aborts where dolfinx's C++ is loaded (as other tests load it here)
    np.savez(tmp_path / "res.npz", geometry=res["geometry"], topology=res["topology"], x=res["fields"]["x"][0.0])
    code = ("import sys, numpy as np; from solver.post.plots import render; d = np.load(sys.argv[1]); "
            "render({'geometry': d['geometry'], 'topology': d['topology'], 'times': [0.0], "
            "'fields': {'x': {0.0: d['x']}}}, 'x', 0.0, 1.0, sys.argv[2], 'x', cmap='turbo')")
    done = subprocess.run([sys.executable, "-c", code, str(tmp_path / "res.npz"), str(tmp_path / "x.png")], cwd=ROOT,
                          capture_output=True, text=True, timeout=300)
    assert done.returncode == 0, done.stderr[-2000:]
    img = (mpimg.imread(tmp_path / "x.png")[..., :3] * 255).astype(float)
    lut = matplotlib.colormaps["turbo"](np.linspace(0, 1, 256))[:, :3] * 255
    body = img[:, : int(0.8 * img.shape[1])]  # left of the colour bar
    rgb = body.reshape(-1, 3)
    chroma = rgb.max(axis=1) - rgb.min(axis=1)
    coloured = chroma > 40  # not the white background, grey edges or black text
    assert coloured.sum() > 20_000
    d = np.linalg.norm(rgb[coloured][:, None, :] - lut[None, :, :], axis=2)
    nearest = d.min(axis=1)
    assert np.quantile(nearest, 0.98) < 8.0, np.quantile(nearest, [0.5, 0.9, 0.98])
    if not solid:
        value = d.argmin(axis=1) / 255.0  # the bar runs over this picture's range, 0 to 1
        column = np.nonzero(coloured)[0] % body.shape[1]
        x = (column - column.min()) / (column.max() - column.min())  # the drawn field, from the pixel's column
        # measured: median 0.002, 95 % 0.004 unlit; lit (lighting=True) 0.037 and 0.091, its colours 50 RGB units off
        assert np.quantile(np.abs(value - x), 0.95) < 0.02


def test_a_3d_contact_part_is_drawn_as_a_map_of_its_face(tmp_path):
    """In 3-D the face z = 0 is drawn head-on in its own coordinates x, y (not against an arc length)."""
    pytest.importorskip("matplotlib")
    from solver.post.plots import contact_profiles, face_coordinates

    g = np.linspace(0.0, 1.0, 9)
    x, y = (a.ravel() for a in np.meshgrid(g, g))
    pen = 1e-3 * (0.25 - (x - 0.5) ** 2 - (y - 0.5) ** 2)
    level = {"t": np.ones_like(x), "s": np.arange(x.size, dtype=float), "x": x, "y": y, "z": 0 * x, "gap": 0 * x,
             "u_normal": pen, "penetration": pen, "pressure": np.maximum(pen, 0) * 1e4}
    made = contact_profiles({(3, "bottom"): level}, tmp_path, dim=3)
    assert [p.name for p in made] == ["contact_bottom.png"]
    xy, labels = face_coordinates(np.column_stack([x, y, 0 * x]))
    assert np.array_equal(xy, np.column_stack([x, y])) and labels == ("x (model units)", "y (model units)")
    tilted, labels = face_coordinates(np.column_stack([x, y, x + y]))
    assert labels[0].startswith("first in-plane") and np.ptp(tilted, axis=0).min() > 0.5
