"""The contact term at its quadrature points, as sparse matrices (docs/model.md §3.3, §4).

The fixed-point methods iterate on point values of u_nu - g, and the penetration
diagnostic reads them; both see exactly the discrete term that the UFL form integrates.
"""

from __future__ import annotations

import numpy as np
from mpi4py import MPI

from .config import BoundaryConfig
from .geometry import Geometry


class ContactPoints:
    """The contact term at its quadrature points: u_nu - g = N u - g and j(u) = N^T W p(N u - g).

    N (sparse, local dofs incl. ghosts -> points of the facets this rank integrates) and the
    weights W reproduce the ``ds`` rule of :func:`residual` exactly, so every method works on
    the same discrete contact term. Used by the fixed-point methods and for the penetration.
    """

    def __init__(self, geo: Geometry, V, parts: tuple[BoundaryConfig, ...], degree: int) -> None:
        import basix
        import scipy.sparse as sp

        mesh = geo.mesh
        tdim, fdim = mesh.topology.dim, mesh.topology.dim - 1
        if tdim != 2:
            raise NotImplementedError("ContactPoints: 2-D meshes only")
        mesh.topology.create_connectivity(fdim, tdim)
        mesh.topology.create_connectivity(fdim, 0)
        f2c, f2v = mesh.topology.connectivity(fdim, tdim), mesh.topology.connectivity(fdim, 0)
        c2v = mesh.topology.connectivity(tdim, 0)
        ncells = mesh.topology.index_map(tdim).size_local
        x = V.tabulate_dof_coordinates()  # by dof node: topology vertex numbers are not geometry node numbers
        s, wq = basix.make_quadrature(basix.CellType.interval, degree)
        s = s[:, 0]
        bs = V.dofmap.index_map_bs
        rows, cols, vals, weights, gaps, inv_mu = [], [], [], [], [], []
        npts = 0
        for part in parts:
            for f in geo.facets(part.name):
                c = f2c.links(f)[0]
                if c >= ncells:  # integrated by the rank that owns the cell
                    continue
                va, vb = f2v.links(f)
                cell_vertices = list(c2v.links(c))
                dofs = V.dofmap.cell_dofs(c)  # P1: local dof i sits at the cell's vertex i
                da, db = dofs[cell_vertices.index(va)], dofs[cell_vertices.index(vb)]
                xa, xb = x[da, :2], x[db, :2]
                t = xb - xa
                length = float(np.hypot(*t))
                n = np.array([t[1], -t[0]]) / length
                centre = x[dofs, :2].mean(axis=0)
                if np.dot(centre - xa, n) > 0:  # outward
                    n = -n
                for sq, w in zip(s, wq):
                    for dof, phi in ((da, 1.0 - sq), (db, sq)):
                        for comp in range(2):
                            rows.append(npts)
                            cols.append(dof * bs + comp)
                            vals.append(phi * n[comp])
                    weights.append(w * length)
                    gaps.append(part.gap)
                    inv_mu.append(1.0 / part.mu)
                    npts += 1
        size = (V.dofmap.index_map.size_local + V.dofmap.index_map.num_ghosts) * bs
        self.N = sp.csr_matrix((vals, (rows, cols)), shape=(npts, size))
        self.NT = self.N.T.tocsr()
        self.W = np.asarray(weights)
        self.g = np.asarray(gaps)
        self.inv_mu = np.asarray(inv_mu)
        self.comm = geo.comm

    def penetration(self, u_local) -> np.ndarray:
        """u_nu - g at the local points."""
        return self.N @ u_local - self.g

    def max_penetration(self, u_local) -> float:
        r = self.penetration(u_local)
        return self.comm.allreduce(float(r.max()) if r.size else -np.inf, op=MPI.MAX)

    def forces(self, values) -> np.ndarray:
        """N^T W values: nodal forces (local array incl. ghosts; needs a reverse scatter-add)."""
        return self.NT @ (self.W * values)
