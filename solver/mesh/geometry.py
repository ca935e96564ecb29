"""Mesh, named boundary tags and measures: one object the physics terms share."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import ufl
from dolfinx import mesh as dmesh
from dolfinx.cpp.mesh import entities_to_geometry
from mpi4py import MPI

from solver.config import BoundaryConfig, MeshConfig
from solver.config.boundary import FACE_AXIS, face_bounds
from solver.errors import ConfigError

_DIAGONAL = {
    "right": dmesh.DiagonalType.right,
    "left": dmesh.DiagonalType.left,
    "right/left": dmesh.DiagonalType.right_left,
    "left/right": dmesh.DiagonalType.left_right,
    "crossed": dmesh.DiagonalType.crossed,
}


@dataclass
class Geometry:
    """The mesh, its facet tags, a name -> tag map, and the ``dx``/``ds`` measures."""

    mesh: dmesh.Mesh
    facet_tags: dmesh.MeshTags
    tags: dict[str, int]
    ds: ufl.Measure

    @property
    def comm(self) -> MPI.Comm:
        return self.mesh.comm

    @property
    def dim(self) -> int:
        return self.mesh.topology.dim

    def facets(self, name: str) -> np.ndarray:
        """Local facet indices of the named part."""
        return self.facet_tags.indices[self.facet_tags.values == self.tags[name]]

    def measure(self, name: str) -> float:
        """Length (area) of a named boundary part, summed over ranks: |F| = |x1 - x0| for a segment,
        |(x1 - x0) x (x2 - x0)| / 2 for a triangle, over the owned facets (affine facets, as the built-in and
        gmsh meshes have). From the coordinates, not a form: a form's compiled module is named after its mesh,
        so every mesh would compile it again."""
        fdim = self.dim - 1
        facets = self.facets(name)
        facets = facets[facets < self.mesh.topology.index_map(fdim).size_local]

        self.mesh.topology.create_connectivity(fdim, 0)
        nodes = entities_to_geometry(self.mesh._mesh, fdim, facets.astype(np.int32), False)  # the C++ mesh (0.5.2)
        x = self.mesh.geometry.x[nodes.reshape(-1)].reshape(len(facets), fdim + 1, 3)  # (a rank may own none)
        if fdim == 1:
            size = np.linalg.norm(x[:, 1] - x[:, 0], axis=1)
        else:
            size = 0.5 * np.linalg.norm(np.cross(x[:, 1] - x[:, 0], x[:, 2] - x[:, 0]), axis=1)
        return self.comm.allreduce(float(size.sum()), op=MPI.SUM)

    def num_cells(self) -> int:
        imap = self.mesh.topology.index_map(self.dim)
        return imap.size_global


def _side_marker(side: str, corners, interval, tol: float):
    (x0, y0), (x1, y1) = corners
    pos = {"left": (0, x0), "right": (0, x1), "bottom": (1, y0), "top": (1, y1)}[side]
    axis, value = pos
    along = 1 - axis

    def marker(x: np.ndarray) -> np.ndarray:
        on = np.isclose(x[axis], value, atol=tol)
        if interval is not None:
            on &= (x[along] >= interval[0] - tol) & (x[along] <= interval[1] + tol)
        return on

    return marker


def equispaced(msh: dmesh.Mesh) -> dmesh.Mesh:
    """The mesh with its UFL coordinate element marked ``variant="equispaced"`` from the start.

    FFCx 0.5 marks it so itself, in place on the mesh's UFL domain, when it first compiles a form on that mesh
    (``ffcx/analysis.py``), after that form's signature was taken. The signatures of the forms made after then
    depend on whether an earlier form was compiled (the domain mutated) or found in the disk cache (not): on an
    empty cache the same model built twice would name a form differently. Marked at creation,
    every signature is the same whatever the cache holds. The variant changes no number of a degree-1 geometry
    (its only nodes are the vertices); ``dolfinx.io.gmshio`` already makes its meshes this way.
    """
    element = msh.ufl_domain().ufl_coordinate_element()
    sub = element.sub_elements()[0]
    if sub.variant() is not None:
        return msh
    sub = ufl.FiniteElement(sub.family(), sub.cell(), sub.degree(), sub.quadrature_scheme(), variant="equispaced")
    return dmesh.Mesh(msh._mesh, ufl.Mesh(ufl.VectorElement(sub, dim=element.value_shape()[0])))


def _rectangle(comm: MPI.Comm, cfg: MeshConfig, parts: tuple[BoundaryConfig, ...]):
    (x0, y0), (x1, y1) = cfg.corners
    msh = equispaced(dmesh.create_rectangle(
        comm, [np.array([x0, y0]), np.array([x1, y1])], [cfg.nx, cfg.ny],
        cell_type=dmesh.CellType.triangle, diagonal=_DIAGONAL[cfg.diagonal],
    ))
    tol = 1e-10 * max(x1 - x0, y1 - y0)
    ft, tags = _tag(msh, parts, lambda part: _side_marker(part.side, cfg.corners, part.interval, tol))
    return msh, ft, tags


def _face_marker(side: str, corners, patch, tol: float):
    """Points on a box face (and inside its sub-rectangle, if any)."""
    axis, which = FACE_AXIS[side]
    value = corners[which][axis]
    along = [a for a in range(3) if a != axis]

    def marker(x: np.ndarray) -> np.ndarray:
        on = np.isclose(x[axis], value, atol=tol)
        if patch is not None:
            for a, (lo, hi) in zip(along, patch):
                on &= (x[a] >= lo - tol) & (x[a] <= hi + tol)
        return on

    return marker


def _tag(msh: dmesh.Mesh, parts: tuple[BoundaryConfig, ...], marker_of) -> tuple[dmesh.MeshTags, dict[str, int]]:
    """Facet tags 1, 2, ... of the parts, in order; ``marker_of(part)`` says which boundary points it holds."""
    fdim = msh.topology.dim - 1
    tags = {}
    indices, values = [], []
    for i, part in enumerate(parts, start=1):
        facets = dmesh.locate_entities_boundary(msh, fdim, marker_of(part))
        indices.append(facets)
        values.append(np.full(len(facets), i, dtype=np.int32))
        tags[part.name] = i
    idx = np.concatenate(indices) if indices else np.empty(0, np.int32)
    val = np.concatenate(values) if values else np.empty(0, np.int32)
    order = np.argsort(idx)
    return dmesh.meshtags(msh, fdim, idx[order].astype(np.int32), val[order]), tags


def _box(comm: MPI.Comm, cfg: MeshConfig, parts: tuple[BoundaryConfig, ...]):
    """The box [corners] cut into nx x ny x nz hexahedra of 6 tetrahedra each; faces tagged like a rectangle's sides."""
    p0, p1 = (np.array(c, dtype=float) for c in cfg.corners)
    msh = equispaced(dmesh.create_box(comm, [p0, p1], [cfg.nx, cfg.ny, cfg.nz], cell_type=dmesh.CellType.tetrahedron))
    tol = 1e-10 * float(np.max(p1 - p0))
    ft, tags = _tag(msh, parts, lambda part: _face_marker(part.side, cfg.corners, part.patch, tol))
    return msh, ft, tags


def _gmsh(comm: MPI.Comm, cfg: MeshConfig, gdim: int):
    import gmsh
    from dolfinx.io import gmshio

    names: dict[str, int] = {}
    domain = True
    if comm.rank == 0:
        gmsh.initialize()
        gmsh.option.setNumber("General.Terminal", 0)
        gmsh.model.add("scene")
        gmsh.merge(cfg.file)
        for dim, tag in gmsh.model.getPhysicalGroups(dim=gdim - 1):
            names[gmsh.model.getPhysicalName(dim, tag) or str(tag)] = tag
        # gmshio takes the cells from the physical groups of dimension gdim: without one it fails deep inside
        domain = bool(gmsh.model.getPhysicalGroups(dim=gdim))
        if not domain:
            gmsh.finalize()
    names, domain = comm.bcast((names, domain), root=0)
    if not domain:
        raise ConfigError(f"mesh.file = {cfg.file!r}: the mesh has no physical group of dimension {gdim} (the body's "
                          f"cells, named 'domain' in meshes/README.md); add one, and one of dimension {gdim - 1} for "
                          "each boundary part")
    try:
        msh, _, ft = gmshio.model_to_mesh(gmsh.model, comm, 0, gdim=gdim)
    finally:
        if comm.rank == 0:
            gmsh.finalize()
    return msh, ft, names


def build(comm: MPI.Comm, cfg: MeshConfig, parts: tuple[BoundaryConfig, ...], gdim: int = 2) -> Geometry:
    """Make the mesh and tag the named boundary parts; check every part is found."""
    if cfg.kind == "rectangle":
        msh, ft, tags = _rectangle(comm, cfg, parts)
    elif cfg.kind == "box":
        msh, ft, tags = _box(comm, cfg, parts)
    else:
        msh, ft, tags = _gmsh(comm, cfg, gdim)
        missing = [p.name for p in parts if p.name not in tags]
        if missing:
            raise ConfigError(
                f"boundary.{missing[0]}: no physical group of that name in {cfg.file}; "
                f"it has: {', '.join(sorted(tags)) or 'none'}"
            )
    ds = ufl.Measure("ds", domain=msh, subdomain_data=ft)
    geo = Geometry(msh, ft, tags, ds)
    if cfg.kind == "rectangle":
        (x0, y0), (x1, y1) = cfg.corners
        for part in parts:
            lo, hi = part.interval or ((x0, x1) if part.side in ("bottom", "top") else (y0, y1))
            length = geo.measure(part.name)
            if abs(length - (hi - lo)) > 1e-8 * (hi - lo):
                raise ConfigError(
                    f"boundary.{part.name}.interval = {[lo, hi]}: the mesh ({cfg.nx}x{cfg.ny}) has no nodes at its ends "
                    f"(found length {length:.6g}); choose nx, ny so that the ends fall on mesh nodes"
                )
    elif cfg.kind == "box":
        for part in parts:
            (a0, a1), (b0, b1) = part.patch or face_bounds(part.side, cfg.corners)
            area, want = geo.measure(part.name), (a1 - a0) * (b1 - b0)
            if abs(area - want) > 1e-8 * want:
                raise ConfigError(
                    f"boundary.{part.name}.interval = {[[a0, a1], [b0, b1]]}: the mesh ({cfg.nx}x{cfg.ny}x{cfg.nz}) has "
                    f"no nodes on its edges (found area {area:.6g}); choose nx, ny, nz so that they fall on mesh nodes"
                )
    else:
        for part in parts:
            if geo.measure(part.name) <= 0:
                raise ConfigError(f"boundary.{part.name}: the physical group has no facets in {cfg.file}")
    return geo
