"""Mesh for a 3-D scene with gmsh physical groups: a cylindrical column pressed onto a foundation.

The column is the cylinder of radius 0.5 and height 1 on the axis x = y = 0.5, z in (0, 1).

Physical groups written to the .msh file:
  dimension 3: "domain"   the cylinder (dolfinx takes its cells from it)
  dimension 2: "top"      the disc z = 1   (a rigid plate: prescribed displacement)
               "bottom"   the disc z = 0   (normal-compliance contact with the foundation)
               "side"     the lateral surface (traction-free)

    python meshes/column3d.py                 # writes meshes/column3d.msh
    python meshes/column3d.py --h 0.05 --output /tmp/column-fine.msh
"""

from __future__ import annotations

import sys
from pathlib import Path

import gmsh

sys.path.insert(0, str(Path(__file__).resolve().parent))
from _gmsh_common import main  # noqa: E402

DEFAULT_H = 0.1


def build(h: float) -> None:
    """Geometry and physical groups in the current gmsh model (main() meshes and writes it)."""
    occ = gmsh.model.occ
    volume = occ.addCylinder(0.5, 0.5, 0.0, 0.0, 0.0, 1.0, 0.5)
    occ.synchronize()
    groups: dict[str, list[int]] = {"top": [], "bottom": [], "side": []}
    for _, surface in gmsh.model.getEntities(2):
        z = occ.getCenterOfMass(2, surface)[2]
        groups["top" if abs(z - 1.0) < 1e-9 else "bottom" if abs(z) < 1e-9 else "side"].append(surface)
    for tag, (name, surfaces) in enumerate(groups.items(), start=1):
        gmsh.model.addPhysicalGroup(2, surfaces, tag)
        gmsh.model.setPhysicalName(2, tag, name)
    gmsh.model.addPhysicalGroup(3, [volume], 10)
    gmsh.model.setPhysicalName(3, 10, "domain")
    gmsh.option.setNumber("Mesh.MeshSizeMax", h)


if __name__ == "__main__":
    main("column3d", build, DEFAULT_H, __doc__.splitlines()[0], dim=3)
