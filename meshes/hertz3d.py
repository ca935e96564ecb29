"""Mesh for the 3-D Hertz scenes: a quarter of a block pressed onto a sphere, graded towards the contact.

The block is (0, L)³ (L = --size, default 2); x = 0 and y = 0 are symmetry planes, the contact is around the origin
on z = 0. The mesh size is --h within --near of the origin (default 0.15 L) and grows linearly to --far (default
0.2 L) at distance --grade (default √3 L, the far corner): gmsh's Distance and Threshold fields. --refine n then
splits every tetrahedron into 8, n times (gmsh's uniform refinement): nested meshes of one graded family, every
size halved at each step (what a convergence study needs; a smaller --h alone refines only near the contact).

Physical groups written to the .msh file:
  dimension 3: "domain"   the block
  dimension 2: "bottom"   z = 0 (contact with the sphere)
               "top"      z = L (pushed down, or clamped)
               "sym_x"    x = 0 (u_x = 0)
               "sym_y"    y = 0 (u_y = 0)
               "free"     x = L and y = L (traction-free)

    python meshes/hertz3d.py --h 0.015 --output /tmp/hertz3d.msh          (demos/hertz3d.py, benchmarks/first_contact.py)
    python meshes/hertz3d.py --size 1 --h 0.03 --grade 0.6 --refine 1     (scripts/hertz_contact.py)
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

import gmsh

sys.path.insert(0, str(Path(__file__).resolve().parent))
from _gmsh_common import OPTIONS, _set_option  # noqa: E402


def build(h: float, size: float, near: float, far: float, grade: float) -> None:
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
    corner = [p for _, p in gmsh.model.getEntities(0) if max(abs(c) for c in gmsh.model.getValue(0, p, [])) < 1e-9]
    field = gmsh.model.mesh.field
    dist = field.add("Distance")
    field.setNumbers(dist, "PointsList", corner[:1])
    thr = field.add("Threshold")
    field.setNumber(thr, "InField", dist)
    field.setNumber(thr, "SizeMin", h)
    field.setNumber(thr, "SizeMax", far)
    field.setNumber(thr, "DistMin", near)
    field.setNumber(thr, "DistMax", grade)
    field.setAsBackgroundMesh(thr)
    gmsh.option.setNumber("Mesh.MeshSizeExtendFromBoundary", 0)
    gmsh.option.setNumber("Mesh.MeshSizeFromPoints", 0)


def write(output: Path, h: float, size: float = 2.0, near: float | None = None, far: float | None = None,
          grade: float | None = None, refine: int = 0) -> str:
    """Mesh with the fixed options (--near, --far, --grade default to 0.15 L, 0.2 L, √3 L), refine uniformly
    ``refine`` times and write ``output``; returns a one-line summary."""
    near = 0.15 * size if near is None else near
    far = 0.2 * size if far is None else far
    grade = 3 ** 0.5 * size if grade is None else grade
    gmsh.initialize(readConfigFiles=False)  # ignore any user ~/.gmshrc
    try:
        for option, value in OPTIONS.items():
            _set_option(option, value)
        gmsh.model.add("hertz3d")
        build(h, size, near, far, grade)
        gmsh.model.mesh.generate(3)
        for _ in range(refine):
            gmsh.model.mesh.refine()
        output.parent.mkdir(parents=True, exist_ok=True)
        gmsh.write(str(output))
        cells = len(gmsh.model.mesh.getElementsByType(4)[0])
        nodes = len(gmsh.model.mesh.getNodes()[0])
        split = f", refined {refine} times: h = {h / 2 ** refine:g} at the contact" if refine else ""
        return (f"wrote {output}: {cells} tetrahedra, {nodes} nodes (h = {h} within {near:g} of the contact, "
                f"{far:g} from {grade:g}{split})")
    finally:
        gmsh.finalize()


if __name__ == "__main__":
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--h", type=float, default=0.015, help="mesh size at the contact (default 0.015)")
    parser.add_argument("--size", type=float, default=2.0, help="the block's edge L (default 2)")
    parser.add_argument("--near", type=float, help="radius of the fine zone (default 0.15 L)")
    parser.add_argument("--far", type=float, help="mesh size far from the contact (default 0.2 L)")
    parser.add_argument("--grade", type=float, help="distance where the size reaches --far (default √3 L)")
    parser.add_argument("--refine", type=int, default=0, help="uniform refinements after meshing (default 0)")
    parser.add_argument("--output", type=Path, default=Path(__file__).resolve().parent / "hertz3d.msh")
    a = parser.parse_args()
    if not (a.h > 0 and a.size > 0 and a.refine >= 0):
        parser.error("--h and --size must be > 0, --refine >= 0")
    print(write(a.output, a.h, a.size, a.near, a.far, a.grade, a.refine))
