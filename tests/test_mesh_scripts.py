"""meshes/hertz3d.py, the graded quarter block of the 3-D Hertz scenes: named faces with the block's areas, and
--refine n splitting every tetrahedron into 8 (nested meshes: every size halved)."""

import importlib.util
import json
import subprocess
import sys

import numpy as np
import pytest
from conftest import ROOT


def _load(path, name):
    spec = importlib.util.spec_from_file_location(name, path)
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def _read(msh):
    """(tetrahedra, {face name: area}) of a written .msh file (gmsh's own reader, in a process of its own)."""
    code = ("import gmsh, json, sys, numpy as np\n"
            "gmsh.initialize(readConfigFiles=False); gmsh.option.setNumber('General.Terminal', 0); gmsh.open(sys.argv[1])\n"
            "tets = len(gmsh.model.mesh.getElementsByType(4)[0]); areas = {}\n"
            "for dim, tag in gmsh.model.getPhysicalGroups(2):\n"
            "    total = 0.0\n"
            "    for entity in gmsh.model.getEntitiesForPhysicalGroup(dim, tag):\n"
            "        _, _, nodes = gmsh.model.mesh.getElements(2, entity)\n"
            "        tri = np.array([gmsh.model.mesh.getNode(n)[0] for n in nodes[0]]).reshape(-1, 3, 3)\n"
            "        total += 0.5 * np.linalg.norm(np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0]), axis=1).sum()\n"
            "    areas[gmsh.model.getPhysicalName(dim, tag)] = total\n"
            "print(json.dumps([tets, areas]))\n")
    out = subprocess.run([sys.executable, "-c", code, str(msh)], capture_output=True, text=True, check=True)
    return json.loads(out.stdout.strip().splitlines()[-1])


@pytest.mark.serial
def test_hertz3d_names_the_faces_and_refines_uniformly(tmp_path):
    pytest.importorskip("gmsh")
    mesher = _load(ROOT / "meshes" / "hertz3d.py", "hertz3d_mesh")
    coarse, fine = tmp_path / "coarse.msh", tmp_path / "fine.msh"
    mesher.write(coarse, 0.25, size=1.0, grade=0.6)
    summary = mesher.write(fine, 0.25, size=1.0, grade=0.6, refine=1)
    (n0, areas0), (n1, areas1) = _read(coarse), _read(fine)
    assert n1 == 8 * n0 and f"{n1} tetrahedra" in summary
    expected = {"bottom": 1.0, "top": 1.0, "sym_x": 1.0, "sym_y": 1.0, "free": 2.0}
    for areas in (areas0, areas1):
        assert areas.keys() == expected.keys()
        assert np.allclose([areas[k] for k in expected], list(expected.values()), rtol=1e-12)
