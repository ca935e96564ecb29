"""The contact term at its quadrature points, as sparse matrices (docs/model.md §3.3, §4).

The fixed-point methods iterate on point values of u_nu - g, and the penetration
diagnostic reads them; both see exactly the discrete term that the UFL form integrates.
"""

from __future__ import annotations

import basix
import numpy as np
import scipy.sparse as sp
from mpi4py import MPI

from solver.config import BoundaryConfig
from solver.laws.contact import PointLaws
from solver.mesh.geometry import Geometry
from solver.physics.contact import gap_values
from solver.physics.quadrature import ContactRule, contact_rule


def _facet_frame(facet_vertices, cell_vertices: list, dofs, x: np.ndarray):
    """A boundary facet's end dofs (P1: local dof i sits at the cell's vertex i), outward normal, length and
    its cell's dofs."""
    va, vb = facet_vertices
    da, db = dofs[cell_vertices.index(va)], dofs[cell_vertices.index(vb)]
    xa, xb = x[da, :2], x[db, :2]
    t = xb - xa
    length = float(np.hypot(*t))
    n = np.array([t[1], -t[0]]) / length
    centre = x[dofs, :2].mean(axis=0)
    if np.dot(centre - xa, n) > 0:  # outward
        n = -n
    return da, db, n, length, dofs


def _facet_basis(element, x: np.ndarray, dofs, da, db, s: np.ndarray) -> list:
    """Per facet point s: the (dof, basis value) pairs of the cell's basis (P1: the facet's two hat functions;
    P2 and above: basix orders vertex dofs first, as the cell's vertices)."""
    if element is None:
        return [((da, 1.0 - sq), (db, sq)) for sq in s]
    xa, t = x[da, :2], x[db, :2] - x[da, :2]
    x0 = x[dofs[0], :2]
    J = np.column_stack([x[dofs[1], :2] - x0, x[dofs[2], :2] - x0])
    ref = np.linalg.solve(J, (xa + s[:, None] * t - x0).T).T
    phi = element.tabulate(0, ref)[0, :, :, 0]
    return [tuple(zip(dofs, phi[q])) for q in range(len(s))]


class ContactPoints:
    """The contact term at its quadrature points: u_nu - g = N u - g and j(u) = N^T W p(N u - g).

    The gap g and the law p are evaluated per point as the UFL term does (same ramps; ``laws``: each part's
    :attr:`~solver.config.BoundaryConfig.contact_law` on its points, in its numpy form).

    N (sparse, local dofs incl. ghosts -> points of the facets this rank integrates) and the
    weights W reproduce the ``ds`` rule of :func:`residual` exactly (Gauss or the nodes: ``degree`` is a Gauss degree
    or a :class:`~solver.physics.quadrature.ContactRule`), so every method works on
    the same discrete contact term. Used by the fixed-point methods and for the penetration.
    """

    def __init__(self, geo: Geometry, V, parts: tuple[BoundaryConfig, ...], degree: int | ContactRule) -> None:

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
        s, wq = contact_rule(degree).facet_quadrature(basix.CellType.interval)
        s = s[:, 0]
        bs = V.dofmap.index_map_bs
        degree_u = V.ufl_element().degree()
        # P2 and above: the cell's basis at the points (basix orders vertex dofs first, as the cell's vertices)
        element = basix.create_element(basix.ElementFamily.P, basix.CellType.triangle, degree_u,
                                       basix.LagrangeVariant.gll_warped) if degree_u > 1 else None
        rows, cols, vals, weights, gaps, coords, runs = [], [], [], [], [], [], []
        npts = 0
        for part in parts:
            first = npts
            for f in geo.facets(part.name):
                c = f2c.links(f)[0]
                if c >= ncells:  # integrated by the rank that owns the cell
                    continue
                da, db, n, length, dofs = _facet_frame(f2v.links(f), list(c2v.links(c)), V.dofmap.cell_dofs(c), x)
                basis = _facet_basis(element, x, dofs, da, db, s)
                for q, w in enumerate(wq):
                    for dof, value in basis[q]:
                        for comp in range(2):
                            rows.append(npts)
                            cols.append(dof * bs + comp)
                            vals.append(value * n[comp])
                    weights.append(w * length)
                    coords.append((1.0 - s[q]) * x[da] + s[q] * x[db])
                    npts += 1
            xq = np.array(coords[first:]).reshape(-1, 3)
            gaps.append(gap_values(part, xq))
            runs.append((part.contact_law, npts - first))
        size = (V.dofmap.index_map.size_local + V.dofmap.index_map.num_ghosts) * bs
        self.N = sp.csr_matrix((vals, (rows, cols)), shape=(npts, size))
        self.NT = self.N.T.tocsr()
        self.W = np.asarray(weights)
        self.x = np.array(coords).reshape(-1, 3)  # the points (for tests and pictures)
        self.g = np.concatenate(gaps) if gaps else np.zeros(0)
        self.laws = PointLaws(tuple(runs))
        self.inv_mu = self.laws.column(lambda law: law.stiffness)  # per point: 1/mu (0 where the law has none)
        self.comm = geo.comm

    def penetration(self, u_local) -> np.ndarray:
        """u_nu - g at the local points."""
        return self.N @ u_local - self.g

    def pressure(self, r: np.ndarray) -> np.ndarray:
        """p(r) at the points, each with its part's law."""
        return self.laws.pressure(r)

    def max_penetration(self, u_local) -> float:
        r = self.penetration(u_local)
        return self.comm.allreduce(float(r.max()) if r.size else -np.inf, op=MPI.MAX)

    def forces(self, values) -> np.ndarray:
        """N^T W values: nodal forces (local array incl. ghosts; needs a reverse scatter-add)."""
        return self.NT @ (self.W * values)
