"""Mesh for Example 2 of Campo, Fernandez & Rodriguez-Aros (2008).

Omega = (0,3) x (0,2)  [assumed: the paper prints "[0,2]x[0,3]", but its
boundary parts only fit (0,3) x (0,2); see MODEL.md section 4].

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

import argparse
from pathlib import Path

import gmsh

HERE = Path(__file__).resolve().parent
DEFAULT_H = 0.06

# Mesher options fixed so that regenerating gives the same file.
OPTIONS = {
    "General.Terminal": 0,
    "General.NumThreads": 1,        # single-threaded meshing
    "Mesh.MaxNumThreads2D": 1,
    "General.RandomSeed": 1,        # gmsh >= 4.9 only (skipped if unknown)
    "Mesh.RandomSeed": 1,
    "Mesh.RandomFactor": 1e-9,
    "Mesh.Algorithm": 6,            # Frontal-Delaunay
    "Mesh.ElementOrder": 1,         # linear triangles
    "Mesh.MeshSizeFromCurvature": 0,
    "Mesh.MeshSizeExtendFromBoundary": 1,
    "Mesh.SaveAll": 0,              # write only elements in physical groups
    "Mesh.Binary": 0,               # ASCII
    "Mesh.MshFileVersion": 4.1,     # read by gmsh.merge + dolfinx.io.gmshio.model_to_mesh
}
OPTIONAL = ("General.RandomSeed", "Mesh.RandomSeed", "Mesh.MaxNumThreads2D")


def _set_option(name: str, value: float) -> None:
    try:
        gmsh.option.setNumber(name, value)
    except Exception:  # gmsh raises plain Exception for an unknown option
        if name not in OPTIONAL:
            raise


def build(h: float) -> None:
    """Geometry, physical groups and a linear triangle mesh in the current gmsh model."""
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

    groups = {
        "clamped": [bottom],
        "contact": [left_lower],
        "traction": [right],
        "free": [left_upper, top],
    }
    for tag, (name, curves) in enumerate(groups.items(), start=1):
        gmsh.model.addPhysicalGroup(1, curves, tag)
        gmsh.model.setPhysicalName(1, tag, name)
    gmsh.model.addPhysicalGroup(2, [surface], 10)
    gmsh.model.setPhysicalName(2, 10, "domain")

    gmsh.model.mesh.generate(2)


def main(argv: list[str] | None = None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--h", type=float, default=DEFAULT_H, help=f"target mesh size (default {DEFAULT_H})")
    parser.add_argument("--output", type=Path, default=HERE / "example2.msh", help="output .msh path")
    args = parser.parse_args(argv)
    if not args.h > 0:
        parser.error("--h must be > 0")

    gmsh.initialize(readConfigFiles=False)  # ignore any user ~/.gmshrc
    try:
        # Deterministic, reproducible output: fixed algorithm, seeds, one thread.
        for name, value in OPTIONS.items():
            _set_option(name, value)
        gmsh.model.add("example2")
        build(args.h)
        args.output.parent.mkdir(parents=True, exist_ok=True)
        gmsh.write(str(args.output))
        ntri = len(gmsh.model.mesh.getElementsByType(2)[0])
        nodes = len(gmsh.model.mesh.getNodes()[0])
        print(f"wrote {args.output}: {ntri} triangles, {nodes} nodes (h = {args.h})")
    finally:
        gmsh.finalize()


if __name__ == "__main__":
    main()
