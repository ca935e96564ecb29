"""``python -m solver paraview`` renders a results directory with ParaView's pvbatch (skipped without ParaView)."""

import re
import subprocess
import sys

import numpy as np
import pytest
from conftest import ROOT

import solver.paraview as spv

pytestmark = pytest.mark.serial  # starts its own processes (pvbatch has its own MPI)

RENDER = "import sys; from solver.paraview import main; sys.exit(main(sys.argv[1:]))"


@pytest.fixture(scope="module")
def results(tmp_path_factory):
    """A tiny example-1 run: 6 x 6 mesh, times 0, 0.25, ..., 1."""
    if not spv.available():
        pytest.skip("ParaView (pvbatch) is not installed: apt-get install paraview")
    out = tmp_path_factory.mktemp("paraview") / "r"
    run = [sys.executable, "-m", "solver", "run", "configs/example1.toml", "--output", str(out), "--no-progress",
           "--set", "mesh.nx=6", "--set", "mesh.ny=6", "--set", "time.k=0.25"]
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
    assert {"displacement", "damage", "von_mises", "von_mises_elastic"} <= names
    import matplotlib.image as mpimg

    img = mpimg.imread(png)
    assert img.shape[0] >= 600 and img.shape[1] >= 900
    assert np.unique(img.reshape(-1, img.shape[-1]), axis=0).shape[0] > 50  # a picture, not a blank


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
