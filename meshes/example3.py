"""Mesh for Example 3 of Campo, Fernandez & Rodriguez-Aros (2008).

Omega = (0,2) x (0,1)  [assumed: the paper's Fig. 7 geometry is not in the
text; see docs/model.md §5 and §6].

Physical groups written to the .msh file:
  dimension 2: "domain"    the whole rectangle (dolfinx needs it to get cells)
  dimension 1: "clamped"   {0} x [0,1]   (Gamma_D)
               "contact"   [0,2] x {0}   (Gamma_C, foundation below)
               "loaded"    [0,2] x {1}   (Gamma_F, f2 = (0,-10) for t <= 0.5, then 0)
               "free"      {2} x [0,1]   (traction-free)

    python meshes/example3.py                 # writes meshes/example3.msh
    python meshes/example3.py --h 0.02 --output /tmp/fine.msh
"""

from __future__ import annotations

import sys
from pathlib import Path

import gmsh

sys.path.insert(0, str(Path(__file__).resolve().parent))
from _gmsh_common import add_groups, main  # noqa: E402

DEFAULT_H = 0.035


def build(h: float) -> None:
    """Geometry and physical groups in the current gmsh model (main() meshes and writes it)."""
    geo = gmsh.model.geo
    p = [
        geo.addPoint(0.0, 0.0, 0.0, h),  # 1
        geo.addPoint(2.0, 0.0, 0.0, h),  # 2
        geo.addPoint(2.0, 1.0, 0.0, h),  # 3
        geo.addPoint(0.0, 1.0, 0.0, h),  # 4
    ]
    bottom = geo.addLine(p[0], p[1])
    right = geo.addLine(p[1], p[2])
    top = geo.addLine(p[2], p[3])
    left = geo.addLine(p[3], p[0])
    loop = geo.addCurveLoop([bottom, right, top, left])
    surface = geo.addPlaneSurface([loop])
    geo.synchronize()

    add_groups({
        "clamped": [left],
        "contact": [bottom],
        "loaded": [top],
        "free": [right],
    }, surface)


if __name__ == "__main__":
    main("example3", build, DEFAULT_H, __doc__.splitlines()[0])
