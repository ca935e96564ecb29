"""Local refinement of a scene's mesh with its named boundary parts kept (2-D).

``dolfinx.mesh.refine(mesh, edges)`` (Plaza) refines the marked edges and what closure
needs, in serial and in parallel, but gives the new mesh no facet tags, and
``transfer_facet_meshtag`` works in 0.5.2 only after uniform refinement without ghosts.
So the parts are re-tagged by containment: every exterior facet of the new mesh lies inside
exactly one exterior facet of the old one (refinement only splits facets), and takes that
facet's tag. The old tagged facets are few (the boundary), so every rank gathers all of
them; each rank then tags its own new facets. This works for the built-in rectangles and
for gmsh meshes alike.
"""

from __future__ import annotations

import numpy as np
import ufl
from dolfinx import cpp
from dolfinx import mesh as dmesh

from solver.mesh.geometry import Geometry, equispaced


def _segments(geo: Geometry) -> tuple[np.ndarray, np.ndarray]:
    """All ranks' tagged facets as segments (k, 2, 2) and their tags (k,)."""
    mesh = geo.mesh
    fdim = mesh.topology.dim - 1
    facets = geo.facet_tags.indices
    nodes = cpp.mesh.entities_to_geometry(mesh._mesh, fdim, facets, False)  # Debian's 0.5.2: _mesh is the C++ mesh
    seg = mesh.geometry.x[nodes][:, :, :2] if len(facets) else np.zeros((0, 2, 2))
    parts = geo.comm.allgather((seg, geo.facet_tags.values))
    return np.concatenate([p[0] for p in parts]), np.concatenate([p[1] for p in parts])


def refine(geo: Geometry, cells: np.ndarray) -> Geometry:
    """The mesh with the given local cells refined (their edges marked; Plaza adds what closure needs), its
    boundary parts re-tagged by containment in the old tagged facets. Collective."""
    mesh = geo.mesh
    tdim = mesh.topology.dim
    if tdim != 2:
        raise NotImplementedError("adapt.refine: 2-D meshes only")
    mesh.topology.create_connectivity(tdim, 1)
    c2e = mesh.topology.connectivity(tdim, 1)
    edges = np.unique(c2e.array.reshape(-1, 3)[np.asarray(cells, dtype=np.int32)]).astype(np.int32)
    new = equispaced(dmesh.refine(mesh, edges, redistribute=False))  # refine copies the parent's element as it is now
    fdim = tdim - 1
    new.topology.create_connectivity(fdim, tdim)
    exterior = cpp.mesh.exterior_facet_indices(new.topology)
    mid = dmesh.compute_midpoints(new, fdim, exterior)[:, :2] if len(exterior) else np.zeros((0, 2))
    seg, tag = _segments(geo)
    indices, values = np.empty(0, np.int32), np.empty(0, np.int32)
    if len(exterior) and len(seg):
        a, b = seg[:, 0], seg[:, 1]  # (k, 2)
        ab = b - a
        length2 = np.einsum("kj,kj->k", ab, ab)
        s = np.einsum("fkj,kj->fk", mid[:, None, :] - a[None], ab) / length2  # (facet, segment)
        closest = a[None] + np.clip(s, 0.0, 1.0)[:, :, None] * ab[None]
        dist = np.linalg.norm(mid[:, None, :] - closest, axis=2)
        best = np.argmin(dist, axis=1)
        scale = np.sqrt(length2.max())
        inside = dist[np.arange(len(mid)), best] < 1e-9 * scale
        indices, values = exterior[inside].astype(np.int32), tag[best[inside]].astype(np.int32)
    order = np.argsort(indices)
    ft = dmesh.meshtags(new, fdim, indices[order], values[order])
    return Geometry(new, ft, dict(geo.tags), ufl.Measure("ds", domain=new, subdomain_data=ft))


def refine_uniformly(geo: Geometry) -> Geometry:
    """The mesh with every owned cell refined (4 children each), its boundary parts kept. Collective."""
    mesh = geo.mesh
    return refine(geo, np.arange(mesh.topology.index_map(mesh.topology.dim).size_local))
