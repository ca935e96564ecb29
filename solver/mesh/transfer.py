"""Transfer between meshes: a function's values and gradients at arbitrary points as sparse matrices.

A run's fields are carried to other points (a finer or an adapted mesh's dofs, an error
estimator's probes) by the run's basis tabulated at those points: exact where the meshes
nest and the source degree is at most the target's. Affine triangles and tetrahedra, this process.
"""

from __future__ import annotations

import basix
import numpy as np
import scipy.sparse as sp
from dolfinx import geometry


def locate(mesh, points: np.ndarray):
    """The cell holding each point (affine triangles or tetrahedra), the cell's Jacobian (columns: edges) and the point's
    reference coordinates; raises ValueError if a point lies outside this process's cells."""

    tdim = mesh.topology.dim
    pts = np.zeros((len(points), 3))
    pts[:, : points.shape[1]] = points
    tree = geometry.BoundingBoxTree(mesh, tdim)
    colliding = geometry.compute_colliding_cells(mesh, geometry.compute_collisions(tree, pts), pts)
    offsets = colliding.offsets
    found = np.diff(offsets) > 0
    cells = np.full(len(pts), -1, dtype=np.int32)
    cells[found] = colliding.array[offsets[:-1][found]]
    if not found.all():
        # a point on the boundary off by round-off is in its nearest cell (an adapted mesh's node at x = 1 + 2.2e-16
        # on this machine's BLAS kernel, which dolfinx's collision test, relative to the cell size, misses for cells
        # of 1/256 and smaller); one farther out than round-off is outside
        missing = np.flatnonzero(~found)
        ncells = mesh.topology.index_map(tdim).size_local + mesh.topology.index_map(tdim).num_ghosts
        mid = geometry.create_midpoint_tree(mesh, tdim, np.arange(ncells, dtype=np.int32))
        near = geometry.compute_closest_entity(tree, mid, mesh, pts[missing])
        x = mesh.geometry.x
        size = float(np.ptp(x[:, :tdim], axis=0).max()) if len(x) else 1.0
        if np.any(near < 0) or np.any(np.sqrt(geometry.squared_distance(mesh, tdim, near, pts[missing]))
                                          > 1e-12 * size):
            raise ValueError("a point lies outside the mesh")
        cells[missing] = near
    gdofs = mesh.geometry.dofmap.array.reshape(-1, tdim + 1)[cells]
    X = mesh.geometry.x[gdofs][:, :, :tdim]  # (point, vertex, coordinate)
    J = np.stack([X[:, i] - X[:, 0] for i in range(1, tdim + 1)], axis=2)
    ref = np.linalg.solve(J, (pts[:, :tdim] - X[:, 0])[:, :, None])[:, :, 0]
    return cells, J, ref


def tabulated(V, points: np.ndarray, derivatives: int):
    """V's element basis (and its reference derivatives up to ``derivatives``) at located points, with what a
    sparse matrix over V's local nodes needs: (cells' Jacobians, table (deriv, point, local dof), rows, cols,
    number of columns)."""

    cells, J, ref = locate(V.mesh, points)
    cell = basix.CellType.triangle if V.mesh.topology.dim == 2 else basix.CellType.tetrahedron
    element = basix.create_element(basix.ElementFamily.P, cell, V.ufl_element().degree(),
                                   basix.LagrangeVariant.gll_warped)
    tab = element.tabulate(derivatives, ref)[:, :, :, 0]
    ndofs = tab.shape[2]
    cols = V.dofmap.list.array.reshape(-1, ndofs)[cells].ravel()
    rows = np.repeat(np.arange(len(points)), ndofs)
    size = V.dofmap.index_map.size_local + V.dofmap.index_map.num_ghosts
    return J, tab, rows, cols, size


def interpolation_matrix(V, points: np.ndarray) -> sp.csr_matrix:
    """Rows: points; columns: the nodes of V (a Lagrange space on affine triangles or tetrahedra, this process; for a vector
    space the matrix acts on each component: P @ u.reshape(-1, bs)).

    Each point is located in a cell of V's mesh (bounding-box tree), mapped to the reference
    cell, and V's element basis is tabulated there.
    """
    _, tab, rows, cols, size = tabulated(V, points, 0)
    P = sp.csr_matrix((tab[0].ravel(), (rows, cols)), shape=(len(points), size))
    P.eliminate_zeros()
    return P


def gradient_matrices(V, points: np.ndarray) -> tuple[sp.csr_matrix, ...]:
    """(Dx, Dy) in 2-D, (Dx, Dy, Dz) in 3-D: rows: points; columns: the nodes of V (a Lagrange space on affine
    triangles or tetrahedra); Dx @ u gives du/dx at the points (componentwise for a vector space, as
    :func:`interpolation_matrix`)."""
    J, tab, rows, cols, size = tabulated(V, points, 1)
    Jinv_T = np.transpose(np.linalg.inv(J), (0, 2, 1))  # grad_x = J^{-T} grad_X
    grads = np.einsum("pij,jpd->ipd", Jinv_T, tab[1:])  # (x/y(/z), point, local dof)
    return tuple(sp.csr_matrix((grads[i].ravel(), (rows, cols)), shape=(len(points), size)) for i in range(J.shape[1]))


def petsc_to_scipy(A) -> sp.csr_matrix:
    """A PETSc AIJ matrix (this process's rows) as a scipy CSR matrix."""
    ai, aj, av = A.getValuesCSR()
    return sp.csr_matrix((av, aj, ai), shape=A.getSize())
