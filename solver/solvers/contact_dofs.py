"""The contact dofs B of newton_condensed (docs/model.md §4): the free dofs of the contact facets, their global
order over the ranks, and the block C_BB of the contact Jacobian on them.

A Lagrange trace on a facet depends on the facet's dofs only, so j(u) of a level acts on B alone; the Dirichlet
dofs are left out (their values are the level's, not unknowns).
"""

from __future__ import annotations

import numpy as np
from dolfinx import fem
from dolfinx.fem import petsc as fpetsc
from mpi4py import MPI
from petsc4py import PETSc


class ContactDofs:
    """The free dofs of the contact facets: this rank's owned ones (local indices) and the global order of all
    m of them (rank by rank), with the gathering of their values."""

    def __init__(self, u: fem.Function, facets: np.ndarray, fdim: int, bcs, comm: MPI.Comm) -> None:
        V = u.function_space
        bs = V.dofmap.index_map_bs
        owned = V.dofmap.index_map.size_local * bs
        blocks = fem.locate_dofs_topological(V, fdim, facets)
        local = np.unique((blocks[:, None] * bs + np.arange(bs)[None, :]).ravel())
        local = local[local < owned]
        probe = u.vector.duplicate()
        free = free_mask(probe, bcs)
        probe.destroy()
        self.local = local[free[local]].astype(np.int32)
        self.comm = comm
        counts = comm.allgather(len(self.local))
        self.counts, self.m = counts, int(sum(counts))
        self.offset = int(sum(counts[:comm.rank]))
        self.global_index: np.ndarray | None = None  # their global indices (set at the first use)

    def gather(self, values: np.ndarray) -> np.ndarray:
        """All m values from each rank's owned ones (in the global order)."""
        if self.comm.size == 1:
            return np.array(values, dtype=float)
        out = np.empty(self.m)
        self.comm.Allgatherv(np.ascontiguousarray(values, dtype=float), [out, self.counts])
        return out

    def mine(self, values: np.ndarray) -> np.ndarray:
        """This rank's part of a global m-vector."""
        return values[self.offset:self.offset + len(self.local)]


def free_mask(x: PETSc.Vec, bcs) -> np.ndarray:
    """True at the owned dofs no Dirichlet condition holds (set_bc with two x0 differ exactly there)."""
    one = x.duplicate()
    one.set(1.0)
    x.set(0.0)
    fpetsc.set_bc(x, bcs, one, 1.0)  # g - 1 on the prescribed dofs, 0 elsewhere
    a = x.array_r.copy()
    x.set(0.0)
    fpetsc.set_bc(x, bcs)  # g there
    one.destroy()
    return a == x.array_r


def contact_block(C: PETSc.Mat, dofs: ContactDofs, r0: int) -> np.ndarray:
    """C_BB (m x m, on every rank) from the assembled contact Jacobian. Collective."""
    rows = (dofs.local + r0).astype(np.int32)
    if dofs.global_index is None:
        dofs.global_index = np.concatenate(dofs.comm.allgather(rows)).astype(np.int32)
    block = C.getValues(rows, dofs.global_index).reshape(len(rows), dofs.m) if len(rows) else np.empty((0, dofs.m))
    return block if dofs.comm.size == 1 else np.vstack(dofs.comm.allgather(block))
