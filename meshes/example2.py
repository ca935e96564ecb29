"""Mesh for Example 2 of Campo, Fernandez & Rodriguez-Aros (2008).

Omega = (0,3) x (0,2)  [assumed: the paper prints "[0,2]x[0,3]", but its
boundary parts only fit (0,3) x (0,2); see docs/model.md §5 and §6].

Physical groups written to the .msh file:
  dimension 2: "domain"    the whole rectangle (dolfinx needs it to get cells)
  dimension 1: "clamped"   [0,3] x {0}             (Gamma_D)
               "contact"   {0} x [0,1]             (Gamma_C)
               "traction"  {3} x [0,2]             (Gamma_F, f2 = (-30, 0))
               "free"      {0} x [1,2] u [0,3] x {2} (traction-free)

The left side is split at (0,1), so that point is a mesh vertex and the
contact part ends exactly there.

    python meshes/example2.py                 # writes meshes/example2.msh
    python meshes/example2.py --h 0.03 --output /tmp/fine.msh
"""

from __future__ import annotations

import sys
from pathlib import Path

import gmsh

sys.path.insert(0, str(Path(__file__).resolve().parent))
from _gmsh_common import add_groups, main  # noqa: E402

DEFAULT_H = 0.06


def build(h: float) -> None:
    """Geometry and physical groups in the current gmsh model (main() meshes and writes it)."""
    geo = gmsh.model.geo
    p = [
        geo.addPoint(0.0, 0.0, 0.0, h),  # 1
        geo.addPoint(3.0, 0.0, 0.0, h),  # 2
        geo.addPoint(3.0, 2.0, 0.0, h),  # 3
        geo.addPoint(0.0, 2.0, 0.0, h),  # 4
        geo.addPoint(0.0, 1.0, 0.0, h),  # 5: end of the contact zone
    ]
    bottom = geo.addLine(p[0], p[1])
    right = geo.addLine(p[1], p[2])
    top = geo.addLine(p[2], p[3])
    left_upper = geo.addLine(p[3], p[4])
    left_lower = geo.addLine(p[4], p[0])
    loop = geo.addCurveLoop([bottom, right, top, left_upper, left_lower])
    surface = geo.addPlaneSurface([loop])
    geo.synchronize()

    add_groups({
        "clamped": [bottom],
        "contact": [left_lower],
        "traction": [right],
        "free": [left_upper, top],
    }, surface)


if __name__ == "__main__":
    main("example2", build, DEFAULT_H, __doc__.splitlines()[0])
