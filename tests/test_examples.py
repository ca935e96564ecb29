"""Example 1 at a small mesh: a regression of a few quantities, and parallel runs agreeing with serial."""


import numpy as np
import pytest
from conftest import ROOT, by_cell, by_node, run_cli, solve

from solver.config import load
from solver.io import TIMING_COLUMNS
from solver.post import point_value, read_csv, read_results

# Produced by this code (serial, n = 8, k = 0.05) and reproduced with 2 and 3 ranks to ~1e-14.
# Not a published value: it pins the scheme so that an unintended change shows.
REFERENCE = {
    "u11": (0.004038078162115283, -0.059183604251602226),
    "zeta_min": 0.8244858839271881,
    "zeta_max": 0.9968206680715574,
    "force0": 11.715420495223203,
    "forceT": 11.724135663678483,
    "strain_normT": 0.048875693453917395,
    "zeta_normT": 0.9614843121660148,
}


def test_example1_regression(comm):
    cfg = load(ROOT / "configs/example1.toml", ["mesh.nx=8", "mesh.ny=8", "time.k=0.05"])
    model, rows = solve(cfg, comm)
    assert len(rows) == 21 and rows[-1]["t"] == pytest.approx(1.0)
    assert point_value(model.u, [1.0, 1.0]) == pytest.approx(REFERENCE["u11"], rel=1e-8)
    last = rows[-1]
    assert last["zeta_min"] == pytest.approx(REFERENCE["zeta_min"], rel=1e-8)
    assert last["zeta_max"] == pytest.approx(REFERENCE["zeta_max"], rel=1e-8)
    assert rows[0]["contact_force"] == pytest.approx(REFERENCE["force0"], rel=1e-8)
    assert last["contact_force"] == pytest.approx(REFERENCE["forceT"], rel=1e-8)
    assert last["strain_norm"] == pytest.approx(REFERENCE["strain_normT"], rel=1e-8)
    assert last["zeta_norm"] == pytest.approx(REFERENCE["zeta_normT"], rel=1e-8)
    # the whole bottom is in contact; the active set settles at t = 0 and is reused afterwards
    assert last["contact_length"] == pytest.approx(1.0)
    assert sum(r["factorizations"] for r in rows) <= 3
    assert all(r["newton_iterations"] == 1 for r in rows[1:])


SCENES = {
    "example1": ["--set", "mesh.nx=8", "--set", "mesh.ny=8", "--set", "time.k=0.05", "--set", "output.every=5"],
    "example2": ["--set", "time.k=0.05", "--set", "output.every=10"],
    "example3": ["--set", "time.k=0.05", "--set", "output.every=5"],
    # moving Dirichlet values, reactions, the power law, a gap table, gravity, plane strain
    "foundation": ["--set", "mesh.nx=20", "--set", "mesh.ny=10", "--set", "time.k=0.1", "--set", "output.every=5"],
}


@pytest.fixture(scope="module")
def serial_runs(tmp_path_factory):
    """Each scene run once in one process (shared by the parallel comparisons)."""
    cache = {}

    def get(scene):
        if scene not in cache:
            out = tmp_path_factory.mktemp(scene)
            res = run_cli(["run", f"configs/{scene}.toml", *SCENES[scene], "--no-progress", "--output", str(out / "r")])
            assert res.returncode == 0, res.stderr
            cache[scene] = out / "r"
        return cache[scene]

    return get


@pytest.mark.serial
@pytest.mark.parametrize("nproc", [2, 3])
@pytest.mark.parametrize("scene", list(SCENES))
def test_parallel_equals_serial(tmp_path, serial_runs, scene, nproc):
    """Fields at every written time and every CSV column agree with the serial run to 1e-8."""
    par = run_cli(["run", f"configs/{scene}.toml", *SCENES[scene], "--no-progress", "--output", str(tmp_path / "p")],
               nproc=nproc)
    assert par.returncode == 0, par.stderr
    a, b = read_results(serial_runs(scene)), read_results(tmp_path / "p")
    assert a["times"] == b["times"] and len(a["times"]) >= 3
    for t in a["times"]:
        for name in ("displacement", "damage"):
            assert np.allclose(by_node(a, name, t), by_node(b, name, t), rtol=0, atol=1e-8), (name, t)
        for name in ("stress", "elastic_stress", "von_mises", "von_mises_elastic", "stress_zz"):
            if name in a["fields"]:
                assert np.allclose(by_cell(a, name, t), by_cell(b, name, t), rtol=0, atol=1e-8), (name, t)
    ra, rb = read_csv(serial_runs(scene) / "timeseries.csv"), read_csv(tmp_path / "p/timeseries.csv")
    assert len(ra) == len(rb)
    for x, y in zip(ra, rb):
        for key in x:
            if key not in TIMING_COLUMNS and key != "residual":  # the residual is round-off itself
                assert y[key] == pytest.approx(x[key], rel=1e-8, abs=1e-12), key


@pytest.mark.serial
def test_outputs_open_with_meshio(tmp_path):
    import meshio

    out = tmp_path / "r"
    res = run_cli(["run", "configs/example1.toml", "--set", "mesh.nx=4", "--set", "mesh.ny=4",
                "--set", "time.k=0.25", "--output", str(out), "--no-progress"])
    assert res.returncode == 0, res.stderr
    assert {p.name for p in out.iterdir()} == {"solution.xdmf", "fields", "timeseries.csv", "config.toml", "checkpoint.h5"}
    with meshio.xdmf.TimeSeriesReader(str(out / "solution.xdmf")) as reader:
        points, cells = reader.read_points_cells()
        assert points.shape[0] == 25 and cells[0].data.shape == (32, 3)
        times = []
        for k in range(reader.num_steps):
            t, point_data, cell_data = reader.read_data(k)
            times.append(t)
            assert set(point_data) == {"displacement", "damage"}
            assert set(cell_data) == {"stress", "elastic_stress", "von_mises", "von_mises_elastic"}
            assert point_data["displacement"].shape == (25, 3)  # XDMF pads vectors to 3 components
            assert cell_data["stress"][0].shape == (32, 9)
    assert times == [0.0, 0.25, 0.5, 0.75, 1.0]
    rows = read_csv(out / "timeseries.csv")
    assert [r["t"] for r in rows] == times
    # the resolved config reproduces the run
    again = load(out / "config.toml")
    assert again.mesh.nx == 4 and again.time.k == 0.25


def test_foundation_scene_balances_and_spreads(comm):
    """configs/foundation.toml (coarser): the plate, the foundation and gravity are in equilibrium at every
    level (reaction_top_y + contact force + f_y |Omega| = 0; no net horizontal force on the symmetry plane),
    the contact zone spreads as the plate goes down, and sigma_33 is part of the plane-strain output."""
    from solver.outputs import Outputs

    cfg = load(ROOT / "configs/foundation.toml", ["mesh.nx=20", "mesh.ny=10", "time.k=0.1"])
    model, rows = solve(cfg, comm)
    weight = cfg.body_force.f[0][2] * 2.0  # f_y times the area of (0,2) x (0,1)
    for r in rows:
        assert r["reaction_top_y"] + r["contact_force"] + weight == pytest.approx(0.0, abs=1e-10 * r["contact_force"])
        assert abs(r["reaction_left_x"]) < 1e-10 * r["contact_force"]
    lengths = [r["contact_length"] for r in rows]
    assert lengths[0] < 1.5 and lengths[-1] > lengths[0] + 0.5 and lengths == sorted(lengths)
    assert rows[0]["reaction_top_y"] > 0 > rows[-1]["reaction_top_y"]  # holds the slab up, then pushes it down
    out = Outputs(model, cfg.material, None)
    out.update_cell_fields()
    assert [f.name for f in out.zz] == ["stress_zz", "elastic_stress_zz"]
