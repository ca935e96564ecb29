"""Geometry: named parts on the rectangle and on gmsh meshes, and the checks that run before any output."""

import pytest
from conftest import ROOT

from solver.config import load
from solver.errors import ConfigError
from solver.mesh.geometry import build


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


def test_box_faces_have_their_areas_and_outward_normals(comm):
    import numpy as np
    import ufl
    from dolfinx import fem
    from mpi4py import MPI

    faces = {"left": (0, -1), "right": (0, 1), "front": (1, -1), "back": (1, 1), "bottom": (2, -1), "top": (2, 1)}
    data = {"mesh": {"kind": "box", "corners": [[0.0, -1.0, 0.5], [2.0, 1.0, 1.5]], "nx": 4, "ny": 2, "nz": 2},
            "material": {"model": "3d"},
            "boundary": {name: ({"role": "clamped"} if name == "left" else {"role": "traction", "traction": [0, 0, 0]})
                         for name in faces}}
    from solver.config import from_dict
    cfg = from_dict(data)
    geo = build(comm, cfg.mesh, cfg.boundaries, cfg.dim)
    assert geo.dim == 3 and geo.num_cells() == 6 * 4 * 2 * 2
    area = {"left": 2.0, "right": 2.0, "front": 2.0, "back": 2.0, "bottom": 4.0, "top": 4.0}
    assert {n: geo.measure(n) for n in faces} == pytest.approx(area, rel=1e-12)
    n = ufl.FacetNormal(geo.mesh)
    for name, (axis, sign) in faces.items():
        comps = [comm.allreduce(fem.assemble_scalar(fem.form(n[i] * geo.ds(geo.tags[name]))), op=MPI.SUM)
                 for i in range(3)]
        want = np.zeros(3)
        want[axis] = sign * area[name]
        assert np.allclose(comps, want, atol=1e-12), name


def test_box_sub_rectangles_are_tagged_and_checked(comm):
    from solver.config import from_dict

    parts = {"left": {"role": "clamped"},
             "pad": {"role": "traction", "traction": [0, 0, -1], "side": "top", "interval": [[0.25, 0.75], [0.0, 0.5]]}}
    data = {"mesh": {"kind": "box", "nx": 4, "ny": 4, "nz": 2}, "material": {"model": "3d"}, "boundary": parts}
    cfg = from_dict(data)
    geo = build(comm, cfg.mesh, cfg.boundaries, cfg.dim)
    assert geo.measure("pad") == pytest.approx(0.25, rel=1e-12)
    data["mesh"]["nx"] = 3
    cfg = from_dict(data)
    with pytest.raises(ConfigError, match=r"boundary.pad.interval"):
        build(comm, cfg.mesh, cfg.boundaries, cfg.dim)
