"""Example 1 at a small mesh: a regression of a few quantities, and parallel runs agreeing with serial."""


import numpy as np
import pytest
import regression
from conftest import ROOT, by_cell, by_node, run_cli, solve
from mpi4py import MPI

from solver.config import load
from solver.io.timeseries import TIMING_COLUMNS
from solver.post.results import read_csv, read_results


def test_example1_regression(comm):
    """Example 1 at n = 8, k = 0.05 against tests/data/example1_reference.json (scripts/regenerate_reference.py)."""
    model, rows = solve(load(regression.SCENE, regression.OVERRIDES), comm)
    assert len(rows) == 21 and rows[-1]["t"] == pytest.approx(1.0)
    got, want = regression.quantities(model, rows), regression.load()
    assert set(got) == set(want)
    for key in want:
        assert got[key] == pytest.approx(want[key], rel=1e-8), key
    last = rows[-1]
    # the whole bottom is in contact; the active set settles at t = 0 and is reused afterwards
    assert last["contact_length"] == pytest.approx(1.0)
    assert sum(r["factorizations"] for r in rows) <= 3
    assert all(r["newton_iterations"] == 1 for r in rows[1:])


ALL_FIELDS = ["--set", 'output.fields=["displacement", "damage", "stress", "elastic_stress", "von_mises", '
              '"von_mises_elastic"]']
SCENES = {
    "example1": ["--set", "mesh.nx=8", "--set", "mesh.ny=8", "--set", "time.k=0.05", "--set", "output.every=5", *ALL_FIELDS],
    "example2": ["--set", "time.k=0.05", "--set", "output.every=10", *ALL_FIELDS],
    "example3": ["--set", "time.k=0.05", "--set", "output.every=5", *ALL_FIELDS],
    # P2 and the second-order scheme (the file is example1's)
    "example1_p2_order2": ["--set", "mesh.nx=8", "--set", "mesh.ny=8", "--set", "time.k=0.05", "--set", "output.every=5",
                           "--set", "discretization.u_degree=2", "--set", "time.order=2", *ALL_FIELDS],
    # moving Dirichlet values, reactions, the power law, a gap table, gravity, plane strain (sigma_33 written)
    "foundation": ["--set", "mesh.nx=20", "--set", "mesh.ny=10", "--set", "time.k=0.1", "--set", "output.every=5",
                   "--set", 'output.fields=["displacement", "damage", "stress", "elastic_stress", "von_mises", '
                   '"von_mises_elastic", "stress_zz", "elastic_stress_zz"]'],
}
FILES = {"example1_p2_order2": "example1"}


@pytest.fixture(scope="module")
def serial_runs(tmp_path_factory):
    """Each scene run once in one process (shared by the parallel comparisons)."""
    cache = {}

    def get(scene):
        if scene not in cache:
            out = tmp_path_factory.mktemp(scene)
            res = run_cli(["run", f"configs/{FILES.get(scene, scene)}.toml", *SCENES[scene], "--no-progress",
                           "--output", str(out / "r")])
            assert res.returncode == 0, res.stderr
            cache[scene] = out / "r"
        return cache[scene]

    return get


# every scene on 2 ranks; 3 ranks (an odd partition, a rank with neighbours on both sides) on the gmsh mesh and on P2 with
# the second-order scheme: example1, example3 and foundation on 3 ranks ran the same code as their 2-rank cases
THREE_RANKS = {"example2", "example1_p2_order2"}
CASES = [(scene, nproc) for scene in SCENES for nproc in (2, 3) if nproc == 2 or scene in THREE_RANKS]


@pytest.mark.slow
@pytest.mark.serial
@pytest.mark.parametrize(("scene", "nproc"), CASES, ids=[f"{s}-{n}" for s, n in CASES])
def test_parallel_equals_serial(tmp_path, serial_runs, scene, nproc):
    """Fields at every written time and every CSV column agree with the serial run to 1e-8."""
    par = run_cli(["run", f"configs/{FILES.get(scene, scene)}.toml", *SCENES[scene], "--no-progress", "--output", str(tmp_path / "p")],
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
@pytest.mark.parametrize("fields", ["default", "all"])
def test_outputs_open_with_meshio(tmp_path, fields):
    import meshio

    out = tmp_path / "r"
    res = run_cli(["run", "configs/example1.toml", "--set", "mesh.nx=4", "--set", "mesh.ny=4",
                   "--set", "time.k=0.25", "--output", str(out), "--no-progress", *(ALL_FIELDS if fields == "all" else [])])
    assert res.returncode == 0, res.stderr
    assert {p.name for p in out.iterdir()} == {"solution.xdmf", "contact.xdmf", "fields", "timeseries.csv", "contact.csv",
                                             "config.toml", "checkpoint.h5"}
    with meshio.xdmf.TimeSeriesReader(str(out / "contact.xdmf")) as reader:  # Γ_C: the bottom's 5 vertices, 4 segments
        points, cells = reader.read_points_cells()
        assert points.shape[0] == 5 and cells[0].type == "line" and cells[0].data.shape == (4, 2)
        t, point_data, _ = reader.read_data(reader.num_steps - 1)
        assert t == 1.0 and {"contact_pressure", "gap", "penetration", "normal_displacement"} <= set(point_data)
    cell_fields = {"von_mises", "von_mises_elastic"} | ({"stress", "elastic_stress"} if fields == "all" else set())
    with meshio.xdmf.TimeSeriesReader(str(out / "solution.xdmf")) as reader:
        points, cells = reader.read_points_cells()
        assert points.shape[0] == 25 and cells[0].data.shape == (32, 3)
        times = []
        for k in range(reader.num_steps):
            t, point_data, cell_data = reader.read_data(k)
            times.append(t)
            assert set(point_data) == {"displacement", "damage"}
            assert set(cell_data) == cell_fields
            assert point_data["displacement"].shape == (25, 3)  # vectors padded to 3 components (ParaView warps by them)
            if fields == "all":
                assert cell_data["stress"][0].shape == (32, 6)  # symmetric: XX YY ZZ XY YZ XZ
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
    from solver.io.fields import CellStresses

    cfg = load(ROOT / "configs/foundation.toml", ["mesh.nx=20", "mesh.ny=10", "time.k=0.1"])
    model, rows = solve(cfg, comm)
    weight = cfg.body_force.f[0][2] * 2.0  # f_y times the area of (0,2) x (0,1)
    for r in rows:
        assert r["reaction_top_y"] + r["contact_force"] + weight == pytest.approx(0.0, abs=1e-10 * r["contact_force"])
        assert abs(r["reaction_left_x"]) < 1e-10 * r["contact_force"]
    lengths = [r["contact_length"] for r in rows]
    assert lengths[0] < 1.5 and lengths[-1] > lengths[0] + 0.5 and lengths == sorted(lengths)
    assert rows[0]["reaction_top_y"] > 0 > rows[-1]["reaction_top_y"]  # holds the slab up, then pushes it down
    cells = CellStresses(model, cfg.material)
    elastic = cells.elastic().reshape(-1, 2, 2)
    zz, zz_el = cells.out_of_plane()
    # plane strain: (A eps)_33 = lambda tr eps = nu ((A eps)_11 + (A eps)_22)
    assert np.allclose(zz_el, cfg.material.nu * (elastic[:, 0, 0] + elastic[:, 1, 1]), rtol=1e-12, atol=1e-12)
    assert comm.allreduce(float(np.abs(zz_el).max(initial=0.0)), op=MPI.MAX) > 0 and np.all(np.isfinite(zz))


def test_the_gmsh_3d_column_runs_the_same_on_any_ranks_and_solver(comm):
    """configs/column3d.toml (a gmsh cylinder with named faces, meshes/column3d.py) over 0.2 s: 2 ranks = 1 process,
    and the iterative solver = the direct one, to 1e-7 relative in the contact force and the strain norm."""

    def last(c, linear):
        cfg = load(ROOT / "configs/column3d.toml", ["time.T=0.2", "output.xdmf=false", f"solver.linear={linear}"])
        return solve(cfg, c)[1][-1]

    here = last(comm, "auto")
    alone = last(MPI.COMM_SELF, "auto") if comm.size > 1 else here  # one process: comm is already COMM_SELF's run
    iterative = last(comm, "iterative")
    for key in ("contact_force", "strain_norm", "zeta_min"):
        assert here[key] == pytest.approx(alone[key], rel=1e-7)
        assert iterative[key] == pytest.approx(here[key], rel=1e-7)
    assert here["contact_force"] > 0
