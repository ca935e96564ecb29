"""What the mesh scripts share: fixed gmsh options (reproducible files), the physical
groups, and the command line (``--h``, ``--output``)."""

from __future__ import annotations

import argparse
from collections.abc import Callable
from pathlib import Path

import gmsh

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


def add_groups(groups: dict[str, list[int]], surface: int) -> None:
    """Named dimension-1 groups (tags 1, 2, ...) and the dimension-2 group "domain" (tag 10),
    which dolfinx needs to get cells."""
    for tag, (name, curves) in enumerate(groups.items(), start=1):
        gmsh.model.addPhysicalGroup(1, curves, tag)
        gmsh.model.setPhysicalName(1, tag, name)
    gmsh.model.addPhysicalGroup(2, [surface], 10)
    gmsh.model.setPhysicalName(2, 10, "domain")


def main(name: str, build: Callable[[float], None], default_h: float, description: str,
         argv: list[str] | None = None, dim: int = 2) -> None:
    """Parse --h/--output, mesh with the fixed options (triangles, or tetrahedra with ``dim = 3``) and write
    ``<name>.msh``."""
    parser = argparse.ArgumentParser(description=description)
    parser.add_argument("--h", type=float, default=default_h, help=f"target mesh size (default {default_h})")
    parser.add_argument("--output", type=Path, default=Path(__file__).resolve().parent / f"{name}.msh",
                        help="output .msh path")
    args = parser.parse_args(argv)
    if not args.h > 0:
        parser.error("--h must be > 0")
    gmsh.initialize(readConfigFiles=False)  # ignore any user ~/.gmshrc
    try:
        for option, value in OPTIONS.items():
            _set_option(option, value)
        gmsh.model.add(name)
        build(args.h)
        gmsh.model.mesh.generate(dim)
        args.output.parent.mkdir(parents=True, exist_ok=True)
        gmsh.write(str(args.output))
        cells = len(gmsh.model.mesh.getElementsByType(2 if dim == 2 else 4)[0])
        nodes = len(gmsh.model.mesh.getNodes()[0])
        print(f"wrote {args.output}: {cells} {'triangles' if dim == 2 else 'tetrahedra'}, {nodes} nodes (h = {args.h})")
    finally:
        gmsh.finalize()
