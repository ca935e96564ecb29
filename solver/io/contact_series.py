"""``contact.xdmf``: the contact boundary Γ_C as a dataset of its own, beside ``solution.xdmf``.

Γ_C's facets (segments in 2-D, triangles in 3-D) are written once as a mesh (``fields/contact_mesh.h5``); each written
level holds, at its vertices, the contact results of :class:`solver.physics.contact_traces.ContactTraces`
(``contact_pressure``, ``gap``, ``penetration``, ``normal_displacement``) and the ``displacement`` (so that ParaView
warps Γ_C with the body). Nodes and facets are keyed by the mesh's input indices, as the body's series is: one
process and ``mpirun -n N`` write the same files, and ``--restart`` cuts and continues this series as that one
(:class:`solver.io.xdmf.XDMFSeries` with ``name = "contact"``). Cheap: only Γ_C's vertices are gathered.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
from dolfinx import fem
from mpi4py import MPI

from solver.io.xdmf import FACET_TYPES, DolfinxRows, FieldSpec, Layout, Vector3, XDMFSeries

NAME = "contact"
FIELDS = ("contact_pressure", "gap", "penetration", "normal_displacement")
ATTRIBUTES = {"contact_pressure": "pressure", "gap": "gap", "penetration": "penetration",
              "normal_displacement": "normal_displacement"}  # the field -> the traces' attribute


def facet_layout(geo, names: tuple[str, ...], on_node: np.ndarray) -> Layout:
    """The :class:`Layout` of the facets of the named boundary parts: the owned geometry nodes where ``on_node`` (per
    owned node) is true, the owned facets; keys are the mesh's input indices (a facet's: its sorted nodes' keys
    combined into one integer)."""
    mesh = geo.mesh
    top, g = mesh.topology, mesh.geometry
    tdim, fdim = top.dim, top.dim - 1
    top.create_connectivity(fdim, 0)
    top.create_connectivity(tdim, 0)
    c2v, f2v = top.connectivity(tdim, 0), top.connectivity(fdim, 0)
    cell_nodes = g.dofmap.array
    vertex_node = np.empty(top.index_map(0).size_local + top.index_map(0).num_ghosts, dtype=np.int64)
    vertex_node[c2v.array] = cell_nodes[: len(c2v.array)]  # P1 geometry: a cell's vertices and nodes in the same order
    keys = np.asarray(g.input_global_indices, dtype=np.int64)
    n_owned_facets = top.index_map(fdim).size_local
    facets = np.unique(np.concatenate([geo.facets(name) for name in names]))
    facets = facets[facets < n_owned_facets]
    nodes = np.array([vertex_node[f2v.links(f)] for f in facets], dtype=np.int64).reshape(-1, fdim + 1)
    cells = keys[nodes]
    total = int(mesh.comm.allreduce(int(keys.max(initial=-1)), op=MPI.MAX)) + 1
    ordered = np.sort(cells, axis=1)
    cell_keys = np.zeros(len(cells), dtype=np.int64)
    for k in range(fdim + 1):  # unique up to total^3 < 2^63: some 2 million nodes in 3-D
        cell_keys = cell_keys * total + ordered[:, k]
    owned = np.flatnonzero(on_node)
    return Layout(comm=mesh.comm, points=np.asarray(g.x[owned, : g.dim]), node_keys=keys[owned], cells=cells,
                  cell_keys=cell_keys, cell_type=FACET_TYPES[tdim])


class ContactSeries:
    """Writes Γ_C's facet mesh and, per written level, the contact traces and the displacement at its vertices."""

    def __init__(self, directory: Path, geo, traces, displacement, precision: str,
                 keep_until: float | None = None) -> None:
        self.traces, self.displacement = traces, displacement  # displacement: a callable giving a P1 function
        rows = DolfinxRows(geo.mesh)
        self.rows = rows
        space = traces.pressure.function_space
        node_dof = rows.dofs(space)
        on = np.zeros(len(traces.pressure.x.array), dtype=bool)
        on[traces.on] = True
        self.on_node = on[node_dof]  # per owned geometry node: on Γ_C (the lumped mass there is positive)
        self.node_dof = node_dof[self.on_node]
        layout = facet_layout(geo, tuple(part.name for part in traces.parts), self.on_node)
        specs = [FieldSpec(name, "Node", "Scalar") for name in FIELDS] + [FieldSpec("displacement", "Node", "Vector")]
        self.series = XDMFSeries(directory, layout, specs, precision, keep_until, name=NAME)
        self._vector3 = Vector3()
        self._u_index: tuple | None = None  # (u's space, its owned Γ_C nodes' entries in u.x.array, components)

    def write(self, t: float, left: int | None = None) -> None:
        """Level t (collective); ``left`` as for :meth:`XDMFSeries.write`."""
        values = {name: np.take(getattr(self.traces, ATTRIBUTES[name]).x.array, self.node_dof) for name in FIELDS}
        u: fem.Function = self.displacement()
        values["displacement"] = self._vector3(self._displacement_rows(u))
        self.series.write(t, values, left)

    def _displacement_rows(self, u: fem.Function) -> np.ndarray:
        """u's rows at Γ_C's owned nodes (one take through an index made once per function space)."""
        space = u.function_space
        if self._u_index is None or self._u_index[0] is not space:
            entries = self.rows.entries(space)[self.on_node]
            self._u_index = (space, entries.ravel(), entries.shape[1])
        return np.take(u.x.array, self._u_index[1]).reshape(-1, self._u_index[2])

    def flush(self) -> None:
        self.series.flush()

    def close(self) -> None:
        self.series.close()
