"""Mesh for a 3-D Hertz test: a quarter of a block pressed by a sphere, graded towards the contact.

The block is (0, 1)³; the sphere touches it at the corner x = y = z = 0, so x = 0 and y = 0 are symmetry planes. The
mesh size is ``--h`` within 0.15 of that corner and grows to 0.2 at distance 0.6 (gmsh's Distance and Threshold
fields).

Physical groups written to the .msh file:
  dimension 3: "domain"
  dimension 2: "contact" z = 0 (the sphere's side), "top" z = 1, "xsym" x = 0, "ysym" y = 0, "far" x = 1 and y = 1

    python meshes/hertz_sphere.py --h 0.015 --output /tmp/hertz.msh   (scripts/hertz_contact.py runs it)
"""

from __future__ import annotations

import sys
from pathlib import Path

import gmsh

sys.path.insert(0, str(Path(__file__).resolve().parent))
from _gmsh_common import main  # noqa: E402

DEFAULT_H = 0.03


def build(h: float) -> None:
    """Geometry, size field and physical groups in the current gmsh model (main() meshes and writes it)."""
    occ = gmsh.model.occ
    volume = occ.addBox(0.0, 0.0, 0.0, 1.0, 1.0, 1.0)
    occ.synchronize()
    groups: dict[str, list[int]] = {"contact": [], "top": [], "xsym": [], "ysym": [], "far": []}
    for _, surface in gmsh.model.getEntities(2):
        x, y, z = occ.getCenterOfMass(2, surface)
        name = ("contact" if abs(z) < 1e-9 else "top" if abs(z - 1) < 1e-9 else "xsym" if abs(x) < 1e-9
                else "ysym" if abs(y) < 1e-9 else "far")
        groups[name].append(surface)
    for tag, (name, surfaces) in enumerate(groups.items(), start=1):
        gmsh.model.addPhysicalGroup(2, surfaces, tag)
        gmsh.model.setPhysicalName(2, tag, name)
    gmsh.model.addPhysicalGroup(3, [volume], 10)
    gmsh.model.setPhysicalName(3, 10, "domain")
    origin = [tag for _, tag in gmsh.model.getEntities(0) if max(abs(c) for c in gmsh.model.getValue(0, tag, [])) < 1e-9]
    field = gmsh.model.mesh.field
    distance = field.add("Distance")
    field.setNumbers(distance, "PointsList", origin)
    threshold = field.add("Threshold")
    field.setNumber(threshold, "InField", distance)
    field.setNumber(threshold, "SizeMin", h)
    field.setNumber(threshold, "SizeMax", 0.2)
    field.setNumber(threshold, "DistMin", 0.15)
    field.setNumber(threshold, "DistMax", 0.6)
    field.setAsBackgroundMesh(threshold)
    gmsh.option.setNumber("Mesh.MeshSizeExtendFromBoundary", 0)
    gmsh.option.setNumber("Mesh.MeshSizeFromPoints", 0)


if __name__ == "__main__":
    main("hertz_sphere", build, DEFAULT_H, __doc__.splitlines()[0], dim=3)
