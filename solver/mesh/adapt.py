"""Local refinement of a scene's mesh with its named boundary parts kept (triangles and tetrahedra).

``dolfinx.mesh.refine(mesh, edges)`` (Plaza) refines the marked edges and what closure
needs, in serial and in parallel, but gives the new mesh no facet tags, and
``transfer_facet_meshtag`` works in 0.5.2 only after uniform refinement without ghosts.
So the parts are re-tagged by containment: every exterior facet of the new mesh lies inside
exactly one exterior facet of the old one (refinement only splits facets), and takes that
facet's tag (in 3-D: the midpoint of a new boundary triangle lies in the plane of one old
tagged triangle and inside it). The old tagged facets are few (the boundary), so every rank
gathers all of them; each rank then tags its own new facets. This works for the built-in
rectangles and boxes and for gmsh meshes alike (a curved gmsh boundary is made of flat
facets; refinement puts its new nodes on them, not on the curve).
"""

from __future__ import annotations

import numpy as np
import ufl
from dolfinx import cpp
from dolfinx import mesh as dmesh
from mpi4py import MPI

from solver.mesh.geometry import Geometry, equispaced


def _facets(geo: Geometry) -> tuple[np.ndarray, np.ndarray]:
    """All ranks' tagged facets as simplices (k, dim, dim) (segments in 2-D, triangles in 3-D) and their tags (k,)."""
    mesh = geo.mesh
    dim = mesh.topology.dim
    facets = geo.facet_tags.indices
    nodes = cpp.mesh.entities_to_geometry(mesh._mesh, dim - 1, facets, False)  # Debian's 0.5.2: _mesh is the C++ mesh
    x = mesh.geometry.x[nodes][:, :, :dim] if len(facets) else np.zeros((0, dim, dim))
    parts = geo.comm.allgather((x, geo.facet_tags.values))
    return np.concatenate([p[0] for p in parts]), np.concatenate([p[1] for p in parts])


def _distances(points: np.ndarray, simplices: np.ndarray) -> np.ndarray:
    """(point, simplex): the distance of each point to each segment (2-D) or triangle (3-D), exact where the
    point's projection falls inside (all that containment needs), else an upper bound of it."""
    a = simplices[:, 0]
    d = points[:, None, :] - a[None]  # (point, simplex, dim)
    if simplices.shape[1] == 2:
        ab = simplices[:, 1] - a
        s = np.clip(np.einsum("pkj,kj->pk", d, ab) / np.einsum("kj,kj->k", ab, ab), 0.0, 1.0)
        return np.linalg.norm(d - s[:, :, None] * ab[None], axis=2)
    e1, e2 = simplices[:, 1] - a, simplices[:, 2] - a
    normal = np.cross(e1, e2)
    normal /= np.linalg.norm(normal, axis=1)[:, None]
    height = np.einsum("pkj,kj->pk", d, normal)
    g11, g12, g22 = (np.einsum("kj,kj->k", u, v) for u, v in ((e1, e1), (e1, e2), (e2, e2)))
    r1, r2 = np.einsum("pkj,kj->pk", d, e1), np.einsum("pkj,kj->pk", d, e2)
    det = g11 * g22 - g12**2
    b1, b2 = (g22 * r1 - g12 * r2) / det, (g11 * r2 - g12 * r1) / det  # barycentric coordinates in the plane
    outside = np.maximum(0.0, -np.minimum(np.minimum(b1, b2), 1.0 - b1 - b2)) * np.sqrt(np.maximum(g11, g22))
    return np.abs(height) + outside


def _missing_facets(mesh: dmesh.Mesh) -> int:
    """How many facets no rank integrates: the facets of the mesh less the owned ones with two cells here (the
    interior facets ``dS`` visits) and the owned exterior ones (``ds``). 0 on a correctly ghosted mesh. Collective."""
    tdim = mesh.topology.dim
    mesh.topology.create_entities(tdim - 1)
    mesh.topology.create_connectivity(tdim - 1, tdim)
    facets = mesh.topology.index_map(tdim - 1)
    links = np.diff(mesh.topology.connectivity(tdim - 1, tdim).offsets)[:facets.size_local]
    here = int(np.count_nonzero(links == 2)) + len(cpp.mesh.exterior_facet_indices(mesh.topology))
    return facets.size_global - mesh.comm.allreduce(here, op=MPI.SUM)


def _keep_partition(comm: MPI.Comm, nparts: int, graph, ghosting: bool):
    """A cell partitioner for ``create_mesh`` that leaves every cell on the rank that holds it and ghosts it on the
    ranks of its facet neighbours (``graph`` is dolfinx's distributed dual graph: global cell numbers, in rank order)."""
    n = graph.num_nodes
    start = comm.exscan(n) or 0
    ends = np.array(comm.allgather(start) + [comm.allreduce(n, op=MPI.SUM)])
    cell = np.repeat(np.arange(n), np.diff(graph.offsets))
    owner = np.searchsorted(ends, graph.array, side="right") - 1
    away = owner != comm.rank
    pairs = np.unique(cell[away] * comm.size + owner[away]) if ghosting else np.empty(0, dtype=np.int64)
    ghost_cell, ghost_rank = pairs // comm.size, pairs % comm.size
    offsets = np.zeros(n + 1, dtype=np.int32)
    offsets[1:] = np.cumsum(1 + np.bincount(ghost_cell, minlength=n))
    data = np.empty(offsets[-1], dtype=np.int32)
    data[offsets[:-1]] = comm.rank  # the owner first, then the ranks it is a ghost on
    run = np.arange(len(ghost_cell)) - np.searchsorted(ghost_cell, ghost_cell)
    data[offsets[:-1][ghost_cell] + 1 + run] = ghost_rank
    return cpp.graph.AdjacencyList_int32(data, offsets)


def _ghosted(mesh: dmesh.Mesh) -> dmesh.Mesh:
    """The refined mesh with a complete layer of ghost cells, its cells kept on their ranks.

    dolfinx 0.5.2's ``refine(..., redistribute=False)`` can leave a facet between two ranks with only one of its
    cells on the rank that owns it (seen on the gmsh column in 3-D): neither ``dS`` nor ``ds`` integrates that
    facet, so the estimator's jumps miss it on that partition. Such a mesh is made again from its own cells with
    the partition kept and the ghosts computed from the dual graph. Collective; serial meshes are returned as they
    are."""
    if mesh.comm.size == 1 or _missing_facets(mesh) == 0:
        return mesh
    tdim = mesh.topology.dim
    nodes = mesh.geometry.index_map()
    owned = mesh.topology.index_map(tdim).size_local
    local = mesh.geometry.dofmap.array.reshape(-1, tdim + 1)[:owned]
    cells = nodes.local_to_global(local.ravel()).reshape(local.shape).astype(np.int64)
    x = mesh.geometry.x[:nodes.size_local, :mesh.geometry.dim].copy()
    partitioner = cpp.mesh.create_cell_partitioner(_keep_partition)
    return dmesh.create_mesh(mesh.comm, cells, x, mesh.ufl_domain(), dmesh.GhostMode.shared_facet, partitioner)


# Plaza (dolfinx 0.5.2) bisects each face of a tetrahedron at its longest edge and breaks an exact tie by the global
# index of the opposite vertex, which depends on the partition. In 3-D the refinement is therefore made on the mesh
# mapped by TIE_BREAK (I + 1e-6 B, B fixed and generic), which breaks every tie by the edges' directions alike on any
# partition, and the refined mesh is mapped back (a linear map keeps midpoints, so the new vertices are the edges'
# midpoints to rounding). Measured in docs/guide/accuracy.md (3-D).
TIE_BREAK = np.eye(3) + 1e-6 * np.array([[0.3, 0.7, 0.1], [0.2, -0.4, 0.9], [-0.6, 0.5, 0.8]])


def _plaza(mesh: dmesh.Mesh, edges: np.ndarray) -> dmesh.Mesh:
    """``dolfinx.mesh.refine`` of the marked edges (the children on their parent's rank); in 3-D under TIE_BREAK, so
    that the same marked edges give the same mesh on any number of ranks. ``mesh`` is left as it was. Collective."""
    if mesh.topology.dim != 3:
        return dmesh.refine(mesh, edges, redistribute=False)  # refine copies the parent's element as it is now
    x = mesh.geometry.x
    kept = x.copy()
    x[:] = kept @ TIE_BREAK.T
    try:
        new = dmesh.refine(mesh, edges, redistribute=False)
    finally:
        x[:] = kept
    y = new.geometry.x
    y[:] = np.linalg.solve(TIE_BREAK, y.T).T
    return new


def refine(geo: Geometry, cells: np.ndarray) -> Geometry:
    """The mesh with the given local cells refined (their edges marked; Plaza adds what closure needs), its
    boundary parts re-tagged by containment in the old tagged facets. Collective."""
    mesh = geo.mesh
    tdim = mesh.topology.dim
    mesh.topology.create_connectivity(tdim, 1)
    c2e = mesh.topology.connectivity(tdim, 1)
    n_edges = 3 if tdim == 2 else 6
    edges = np.unique(c2e.array.reshape(-1, n_edges)[np.asarray(cells, dtype=np.int32)]).astype(np.int32)
    new = equispaced(_ghosted(_plaza(mesh, edges)))
    fdim = tdim - 1
    new.topology.create_connectivity(fdim, tdim)
    exterior = cpp.mesh.exterior_facet_indices(new.topology)
    mid = dmesh.compute_midpoints(new, fdim, exterior)[:, :tdim] if len(exterior) else np.zeros((0, tdim))
    simplices, tag = _facets(geo)
    indices, values = np.empty(0, np.int32), np.empty(0, np.int32)
    if len(exterior) and len(simplices):
        scale = float(np.ptp(simplices.reshape(-1, tdim), axis=0).max())
        best = np.empty(len(mid), dtype=np.int64)
        dist = np.empty(len(mid))
        chunk = max(1, 2_000_000 // len(simplices))  # (point, simplex) blocks of a few million entries
        for i in range(0, len(mid), chunk):
            d = _distances(mid[i:i + chunk], simplices)
            best[i:i + chunk] = np.argmin(d, axis=1)
            dist[i:i + chunk] = d[np.arange(len(d)), best[i:i + chunk]]
        inside = dist < 1e-9 * scale
        indices, values = exterior[inside].astype(np.int32), tag[best[inside]].astype(np.int32)
    order = np.argsort(indices)
    ft = dmesh.meshtags(new, fdim, indices[order], values[order])
    return Geometry(new, ft, dict(geo.tags), ufl.Measure("ds", domain=new, subdomain_data=ft))


def refine_uniformly(geo: Geometry) -> Geometry:
    """The mesh with every owned cell refined (4 children each in 2-D, 8 in 3-D), its boundary parts kept.
    Collective."""
    mesh = geo.mesh
    return refine(geo, np.arange(mesh.topology.index_map(mesh.topology.dim).size_local))


def refine_twice(geo: Geometry, cells: np.ndarray, again: np.ndarray | None = None) -> Geometry:
    """The mesh with the given local cells refined, then every cell of the refined mesh that lies inside one of them
    (inside one of ``again``, a subset of them, where given) refined again (h quartered there; Plaza's closure in
    between), boundary parts kept. Collective."""
    from dolfinx import fem

    from solver.mesh.transfer import locate

    finer = refine(geo, cells)
    tdim = finer.mesh.topology.dim
    marked = fem.Function(fem.FunctionSpace(geo.mesh, ("DG", 0)))  # the marks on the ghost cells too
    marked.x.array[:] = 0.0
    marked.x.array[np.asarray(cells if again is None else again, dtype=np.int32)] = 1.0
    marked.x.scatter_forward()
    n = finer.mesh.topology.index_map(tdim).size_local
    mid = dmesh.compute_midpoints(finer.mesh, tdim, np.arange(n, dtype=np.int32))[:, :tdim]
    try:
        inside = marked.x.array[locate(geo.mesh, mid)[0]] > 0.5 if n else np.zeros(0, dtype=bool)
    except ValueError:  # a child off its parent's process: the second refinement is left out on every process
        inside = None
    if not geo.comm.allreduce(inside is not None, op=MPI.LAND):
        return finer
    return refine(finer, np.flatnonzero(inside))
