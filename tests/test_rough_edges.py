"""Rough edges a new user met outside the scene file (issue 32): each a one-line refusal with exit code 2, a
precise --overwrite, and progress lines in a log. Every test here fails on the code before the issue's fixes."""

from __future__ import annotations

import os
import subprocess

import pytest
from conftest import ROOT, mpi_env, solver_cmd
from conftest import run_cli as cli

pytestmark = pytest.mark.serial  # each test starts its own processes

SMALL = ["--set", "mesh.nx=4", "--set", "mesh.ny=4", "--set", "time.k=0.1", "--no-progress"]


def _one_error_line(res, nproc: int = 1) -> str:
    """Exit 2, no traceback, exactly one 'error:' line (the only stderr line on 1 rank)."""
    assert res.returncode == 2, res.stderr[-3000:]
    assert "Traceback" not in res.stderr, res.stderr[-3000:]
    ours = [ln for ln in res.stderr.splitlines() if ln.startswith(("error", "failed", "scene"))]
    assert len(ours) == 1 and ours[0].startswith("error: "), res.stderr
    if nproc == 1:
        assert res.stderr.strip() == ours[0]
    return ours[0]


def _rectangle_msh(path, groups: bool) -> None:
    """A gmsh unit square, with or without physical groups (item 1)."""
    import gmsh

    gmsh.initialize()
    try:
        gmsh.option.setNumber("General.Terminal", 0)
        gmsh.model.add("sq")
        s = gmsh.model.occ.addRectangle(0, 0, 0, 1, 1)
        gmsh.model.occ.synchronize()
        if groups:
            gmsh.model.addPhysicalGroup(2, [s], 10, name="domain")
        gmsh.option.setNumber("Mesh.SaveAll", 0 if groups else 1)
        gmsh.option.setNumber("Mesh.MeshSizeMax", 0.25)
        gmsh.model.mesh.generate(2)
        gmsh.write(str(path))
    finally:
        gmsh.finalize()


@pytest.mark.parametrize("command", ["check", "run"])
@pytest.mark.parametrize("nproc", [1, 2])
def test_gmsh_mesh_without_physical_groups(tmp_path, command, nproc):
    """Item 1: a .msh with no physical groups at all was a 25-line IndexError from gmshio."""
    _rectangle_msh(tmp_path / "bare.msh", groups=False)
    scene = tmp_path / "s.toml"
    scene.write_text('[mesh]\nkind = "gmsh"\nfile = "bare.msh"\n[boundary.left]\nrole = "clamped"\n')
    out = tmp_path / "o"
    args = [command, str(scene)] + (["--output", str(out), "--no-progress"] if command == "run" else [])
    line = _one_error_line(cli(args, nproc), nproc)
    assert "mesh.file" in line and "no physical group of dimension 2" in line and "'domain'" in line
    assert not out.exists()


ROTATION_FREE = """[mesh]
nx = 4
ny = 4
[boundary.left]
role = "displacement"
displacement = ["free", 0.0]
[boundary.bottom]
role = "displacement"
displacement = [0.0, "free"]
[boundary.top]
role = "traction"
traction = [0.0, -1.0]
[time]
T = 0.2
k = 0.1
"""


@pytest.mark.parametrize("command", ["check", "run"])
def test_supports_leaving_a_rotation_free_are_bad_input(tmp_path, command):
    """Item 4: exit 2 (input error), not exit 1 (a failed solve)."""
    scene, out = tmp_path / "s.toml", tmp_path / "o"
    scene.write_text(ROTATION_FREE)
    args = [command, str(scene)] + (["--output", str(out), "--no-progress"] if command == "run" else [])
    line = _one_error_line(cli(args))
    assert "rigid motion free (rotation about (0, 0))" in line and not out.exists()


@pytest.mark.parametrize("item,key", [("mesh.nxx=32", "mesh.nxx"), ("material.E=abc", "material.E"),
                                      ("time.k=-1", "time.k"), ("nosection.a=1", "nosection")])
def test_bad_set_is_blamed_on_set(item, key):
    """Item 6: the error said 'configs/example1.toml: mesh.nxx = 32' as if the file held it."""
    line = _one_error_line(cli(["check", "configs/example1.toml", "--set", item]))
    assert line.startswith(f"error: --set {item}: {key} = "), line


def test_bad_key_in_the_file_is_still_blamed_on_the_file(tmp_path):
    scene = tmp_path / "s.toml"
    scene.write_text("[mesh]\nnxx = 3\n")
    line = _one_error_line(cli(["check", str(scene), "--set", "time.k=0.5"]))
    assert line.startswith(f"error: {scene}: mesh.nxx = 3: unknown key"), line


def test_empty_output_is_refused(tmp_path):
    """Item 7: --output "" silently used the scene's output.directory."""
    line = _one_error_line(cli(["run", "configs/example1.toml", "--output", "", *SMALL], timeout=300))
    assert line.startswith("error: --output '': empty")
    assert not (ROOT / "results" / "example1" / "never").exists()


def _small_run(out, *extra, nproc=1):
    return cli(["run", "configs/example1.toml", "--output", str(out), *SMALL, *extra], nproc)


def test_overwrite_removes_only_what_a_run_writes(tmp_path):
    """Item 8: --overwrite deleted the whole fields/ folder, a user's file in it too."""
    out = tmp_path / "o"
    assert _small_run(out).returncode == 0
    mine = [out / "fields" / "notes.txt", out / "README.md"]
    for f in mine:
        f.write_text("mine")
    res = _small_run(out, "--overwrite", "--set", "time.k=0.25")
    assert res.returncode == 0, res.stderr
    assert all(f.read_text() == "mine" for f in mine)
    assert (out / "fields" / "mesh.h5").exists() and (out / "timeseries.csv").read_text().count("\n") == 1 + 5  # header, levels 0..4
    help_text = cli(["run", "--help"]).stdout
    assert "removes only the files a run writes" in " ".join(help_text.split())


@pytest.mark.parametrize("nproc", [1, 2])
def test_restart_with_a_changed_scene_names_the_key_before_anything_is_printed(tmp_path, nproc):
    """Item 5: the scene header and an empty progress bar came first, and the refusal named no key."""
    out = tmp_path / "o"
    assert _small_run(out, "--set", "output.checkpoint_every=3").returncode == 0
    res = cli(["run", "configs/example1.toml", "--output", str(out), *SMALL, "--set", "output.checkpoint_every=3",
               "--restart", "--set", "material.E=200"], nproc)
    line = _one_error_line(res, nproc)
    assert "material.E = 200.0 (the checkpoint's run had 100.0)" in line and "scene configs" not in res.stderr


def test_check_warns_about_the_disk_a_long_run_fills():
    """Item 9: 10^6 steps written at every level passed check without a word."""
    res = cli(["check", "configs/example1.toml", "--set", "time.T=1e4"])
    assert res.returncode == 0, res.stderr
    warn = [ln for ln in res.stderr.splitlines() if ln.startswith("warning:")]
    assert len(warn) == 1 and "GB (1000001 levels at output.every = 1)" in warn[0], res.stderr
    res = cli(["check", "configs/example1.toml", "--set", "time.T=1e4", "--set", "output.every=1000"])
    assert res.returncode == 0 and "warning" not in res.stderr, res.stderr


def test_progress_in_a_log_is_a_line_every_ten_percent(tmp_path):
    """Item 10: without a terminal the bar was one long line of '\\r' redraws."""
    out = tmp_path / "o"
    cmd = solver_cmd(["run", "configs/example1.toml", "--output", str(out), "--set", "mesh.nx=4", "--set", "mesh.ny=4",
                      "--set", "time.k=0.01"])
    with open(tmp_path / "log", "w") as log:  # a file, as a batch job's log
        assert subprocess.run(cmd, cwd=ROOT, env=mpi_env(), stderr=log, stdout=subprocess.DEVNULL).returncode == 0
    text = (tmp_path / "log").read_text()
    assert "\r" not in text
    lines = [ln for ln in text.splitlines() if "%" in ln and "level" in ln]
    assert 9 <= len(lines) <= 11 and lines[-1].startswith("100% level 101/101"), text
    assert os.path.getsize(tmp_path / "log") < 4000


def test_a_tolerance_out_of_reach_is_refused_at_once_with_nothing_written(tmp_path):
    """Item 2: --tolerance 1e-9 ran 10 minutes to 8.7 GB; with max_dofs it refused after 21 s but left an empty
    output directory. The planner's prediction refuses it after the start meshes, before the directory is made."""
    out = tmp_path / "o"
    res = cli(["run", "configs/example1.toml", "--tolerance", "1e-9", "--output", str(out), "--no-progress"])
    assert res.returncode == 2 and "Traceback" not in res.stderr, res.stderr[-3000:]
    err = [ln for ln in res.stderr.splitlines() if ln.startswith("error")]
    assert len(err) == 1 and "cannot be reached within accuracy.max_dofs: it would need about" in err[0], res.stderr
    assert not out.exists()


@pytest.fixture(scope="module")
def constant_damage(tmp_path_factory):
    """A small run whose damage is zeta* = 0.01 everywhere at every level (as results/hard at T)."""
    out = tmp_path_factory.mktemp("plot") / "o"
    res = cli(["run", "configs/example1.toml", "--output", str(out), *SMALL, "--set", "time.T=0.2",
               "--set", "damage.zeta0=0.01"])
    assert res.returncode == 0, res.stderr
    return out


def test_plot_is_quiet_draws_a_constant_field_readably_and_refuses_times_outside(constant_damage, tmp_path):
    """Items 12-14: a constant field was all black with hidden ticks; every plot printed VTK's yellow X-server
    warning; --times beyond T silently drew the last level."""
    pytest.importorskip("pyvista")
    import numpy as np
    from PIL import Image

    pics = tmp_path / "p"
    res = cli(["plot", str(constant_damage), "--output", str(pics)])
    assert res.returncode == 0 and res.stderr == "", res.stderr  # item 13: no VTK warning, no ANSI colours
    img = np.asarray(Image.open(pics / "damage_final.png").convert("RGB"), dtype=float)
    h, w, _ = img.shape
    body = img[int(0.3 * h):int(0.7 * h), int(0.25 * w):int(0.55 * w)]
    assert body.mean() > 60  # item 12: not black (magma's low end)
    line = _one_error_line(cli(["plot", str(constant_damage), "--output", str(tmp_path / "q"), "--times", "5"]))
    assert line == "error: --times 5: outside the written levels, which span [0, 0.2]" and not (tmp_path / "q").exists()
    res = cli(["plot", str(constant_damage), "--output", str(tmp_path / "r"), "--times", "0.123"])
    assert res.returncode == 0 and "drawn at the nearest written level, t = 0.1" in res.stderr
    assert (tmp_path / "r" / "von_mises_t0_1.png").exists()


def test_study_help_says_what_each_study_is():
    """Item 17: 'study --help' called itself 'stability map and work-precision chart', most options without help."""
    res = cli(["study", "--help"])
    assert res.returncode == 0 and "Table 1 variants, tolerance runs" in " ".join(res.stdout.split())
    res = cli(["study", "stability", "--help"])
    text = " ".join(res.stdout.split())
    assert "mesh (n cells across) of the fine reference" in text and "runs in parallel" in text
