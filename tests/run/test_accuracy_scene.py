"""solver/run/accuracy/scene.py: the scene changes the planner tries."""

from conftest import ROOT

from solver.config import load
from solver.run.accuracy.scene import degrees, elastic, merged, start_mesh, step, time_order, with_changes

SCENE = ROOT / "configs/example1.toml"


def test_zetas_degree_follows_us():
    assert degrees(2) == {"discretization": {"u_degree": 2, "zeta_degree": 2}}


def test_later_changes_win():
    assert merged(step(0.1), {"time": {"T": 2.0}}, step(0.05)) == {"time": {"k": 0.05, "T": 2.0}}
    assert with_changes(load(SCENE), step(0.05), degrees(2)).time.k == 0.05


def test_a_rectangle_starts_with_four_cells_across_its_shorter_side(comm):
    """The unit square's boundary parts end at its corners: 4 x 4 cells already put them on nodes."""
    assert start_mesh(load(SCENE), comm) == {"mesh": {"nx": 4, "ny": 4}}


def test_a_box_starts_with_four_cells_across_its_shortest_side(comm):
    assert start_mesh(load(ROOT / "configs/example1_3d.toml"), comm) == {"mesh": {"nx": 4, "ny": 4, "nz": 4}}
    long = load(ROOT / "configs/example1_3d.toml", ["mesh.corners=[[0, 0, 0], [2, 1, 0.5]]"])
    assert start_mesh(long, comm) == {"mesh": {"nx": 16, "ny": 8, "nz": 4}}


def test_a_gmsh_mesh_starts_as_it_is(comm):
    assert start_mesh(load(ROOT / "configs/example2.toml"), comm) == {}


def test_the_second_order_where_the_scene_allows_it():
    assert time_order(load(SCENE)) == 2


def test_the_elastic_scene_has_no_memory_and_no_damage():
    cfg = elastic(load(SCENE))
    assert cfg.memory.kernel == "none" and not cfg.damage.enabled
    assert cfg.material == load(SCENE).material
