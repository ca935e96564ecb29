"""Geometry: named parts on the rectangle and on gmsh meshes, and the checks that run before any output."""

import pytest
from conftest import ROOT

from solver.config import load
from solver.errors import ConfigError
from solver.geometry import build


def test_rectangle_parts_have_their_lengths(comm):
    cfg = load(ROOT / "configs/example1.toml", ["mesh.nx=4", "mesh.ny=8"])
    geo = build(comm, cfg.mesh, cfg.boundaries, cfg.dim)
    assert {p.name: geo.measure(p.name) for p in cfg.boundaries} == pytest.approx({"left": 1.0, "right": 1.0, "bottom": 1.0})
    assert geo.num_cells() == 2 * 4 * 8


def test_an_interval_off_the_nodes_is_refused(comm):
    cfg = load(ROOT / "configs/example1.toml", ["mesh.nx=3", "mesh.ny=3", "boundary.bottom.interval=[0.0, 0.5]"])
    with pytest.raises(ConfigError, match=r"boundary.bottom.interval"):
        build(comm, cfg.mesh, cfg.boundaries, cfg.dim)


def test_gmsh_groups_are_found_by_name(comm):
    cfg = load(ROOT / "configs/example2.toml")
    geo = build(comm, cfg.mesh, cfg.boundaries, cfg.dim)
    assert set(geo.tags) >= {p.name for p in cfg.boundaries}
    assert all(geo.measure(p.name) > 0 for p in cfg.boundaries)
