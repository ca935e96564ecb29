"""Mesh for the 3-D Hertz scene: a quarter of a block pressed onto a sphere, graded towards the contact.

The block is (0, L) x (0, L) x (0, L) (L = --size, default 2); x = 0 and y = 0 are symmetry planes, the contact is
around the origin on z = 0. The mesh size is --h within --near of the origin and grows linearly to --far at the
block's far corner (a Distance + Threshold field from the origin).

Physical groups written to the .msh file:
  dimension 3: "domain"   the block
  dimension 2: "bottom"   z = 0 (contact with the sphere)
               "top"      z = L (pushed down)
               "sym_x"    x = 0 (u_x = 0)
               "sym_y"    y = 0 (u_y = 0)
               "free"     x = L and y = L (traction-free)

    python meshes/hertz3d.py --h 0.015 --output /tmp/hertz3d.msh
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

import gmsh

sys.path.insert(0, str(Path(__file__).resolve().parent))
from _gmsh_common import OPTIONS, _set_option  # noqa: E402


def build(h: float, near: float, far: float, size: float) -> None:
    """Geometry, physical groups and the graded size field in the current gmsh model."""
    occ = gmsh.model.occ
    volume = occ.addBox(0.0, 0.0, 0.0, size, size, size)
    occ.synchronize()
    groups: dict[str, list[int]] = {"bottom": [], "top": [], "sym_x": [], "sym_y": [], "free": []}
    for _, surface in gmsh.model.getEntities(2):
        x, y, z = occ.getCenterOfMass(2, surface)
        name = ("bottom" if abs(z) < 1e-9 else "top" if abs(z - size) < 1e-9 else "sym_x" if abs(x) < 1e-9
                else "sym_y" if abs(y) < 1e-9 else "free")
        groups[name].append(surface)
    for tag, (name, surfaces) in enumerate(groups.items(), start=1):
        gmsh.model.addPhysicalGroup(2, surfaces, tag)
        gmsh.model.setPhysicalName(2, tag, name)
    gmsh.model.addPhysicalGroup(3, [volume], 10)
    gmsh.model.setPhysicalName(3, 10, "domain")
    origin = gmsh.model.occ.addPoint(0.0, 0.0, 0.0)
    occ.synchronize()
    corner = [p for _, p in gmsh.model.getEntities(0) if max(abs(c) for c in gmsh.model.getValue(0, p, [])) < 1e-9]
    field = gmsh.model.mesh.field
    dist = field.add("Distance")
    field.setNumbers(dist, "PointsList", corner[:1] or [origin])
    thr = field.add("Threshold")
    field.setNumber(thr, "InField", dist)
    field.setNumber(thr, "SizeMin", h)
    field.setNumber(thr, "SizeMax", far)
    field.setNumber(thr, "DistMin", near)
    field.setNumber(thr, "DistMax", size * 3 ** 0.5)
    field.setAsBackgroundMesh(thr)
    gmsh.option.setNumber("Mesh.MeshSizeExtendFromBoundary", 0)
    gmsh.option.setNumber("Mesh.MeshSizeFromPoints", 0)


def write(output: Path, h: float, near: float = 0.3, far: float = 0.4, size: float = 2.0) -> str:
    """Mesh with the fixed options and write ``output``; returns a one-line summary."""
    gmsh.initialize(readConfigFiles=False)
    try:
        for option, value in OPTIONS.items():
            _set_option(option, value)
        gmsh.model.add("hertz3d")
        build(h, near, far, size)
        gmsh.model.mesh.generate(3)
        output.parent.mkdir(parents=True, exist_ok=True)
        gmsh.write(str(output))
        cells = len(gmsh.model.mesh.getElementsByType(4)[0])
        nodes = len(gmsh.model.mesh.getNodes()[0])
        return f"wrote {output}: {cells} tetrahedra, {nodes} nodes (h = {h} within {near} of the contact, {far} far)"
    finally:
        gmsh.finalize()


if __name__ == "__main__":
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--h", type=float, default=0.015, help="mesh size at the contact (default 0.015)")
    parser.add_argument("--near", type=float, default=0.3, help="radius of the fine zone (default 0.3)")
    parser.add_argument("--far", type=float, default=0.4, help="mesh size far from the contact (default 0.4)")
    parser.add_argument("--size", type=float, default=2.0, help="the block's edge L (default 2)")
    parser.add_argument("--output", type=Path, default=Path(__file__).resolve().parent / "hertz3d.msh")
    a = parser.parse_args()
    print(write(a.output, a.h, a.near, a.far, a.size))
