"""Mesh for Example 3 of Campo, Fernandez & Rodriguez-Aros (2008).

Omega = (0,2) x (0,1)  [assumed: the paper's Fig. 7 geometry is not in the
text; see MODEL.md section 4].

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

import argparse
from pathlib import Path

import gmsh

HERE = Path(__file__).resolve().parent
DEFAULT_H = 0.035

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

    groups = {
        "clamped": [left],
        "contact": [bottom],
        "loaded": [top],
        "free": [right],
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
    parser.add_argument("--output", type=Path, default=HERE / "example3.msh", help="output .msh path")
    args = parser.parse_args(argv)
    if not args.h > 0:
        parser.error("--h must be > 0")

    gmsh.initialize(readConfigFiles=False)  # ignore any user ~/.gmshrc
    try:
        # Deterministic, reproducible output: fixed algorithm, seeds, one thread.
        for name, value in OPTIONS.items():
            _set_option(name, value)
        gmsh.model.add("example3")
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
