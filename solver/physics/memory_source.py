"""The fast evaluation of the memory's integrand H = zeta Phi_L(A eps(u)) and of its force on the nodes.

The law is :class:`solver.laws.memory.MemoryIntegrand`, its UFL form the definition and its numpy form the one used
here, on the compact strain components that one product with the strain operator E gives (2-D: a sparse matrix;
3-D: :class:`StrainMap`, the same product from a table), with the pieces that share the strain: the out-of-plane
H_33 of plane strain, the strain norm of the diagnostics, and B M = (M, eps(w)) from the same strain operator.
"""

from __future__ import annotations

import math

import dolfinx.fem.petsc  # noqa: F401  (fem.petsc)
import numpy as np
import scipy.sparse as sp
import ufl
from dolfinx import fem
from mpi4py import MPI
from petsc4py import PETSc

from solver.laws.memory import MemoryIntegrand, pairs
from solver.physics.quadrature import QuadratureRule


def _equal(a: np.ndarray, b: np.ndarray) -> bool:
    """a == b entry by entry (exact; NaN equals nothing); for a long array a sample of about 64 entries first
    settles most unequal pairs at once (a short one is compared whole: one pass costs less than two calls)."""
    if a.shape != b.shape:
        return False
    if a.size > 4096:
        stride = a.size // 64
        if not (a[::stride] == b[::stride]).all():
            return False
    return bool((a == b).all())


class StrainMap:
    """E: u's dofs -> the d(d+1)/2 independent components of eps(u) at the rule's points (one block of ``size_q`` rows
    per component, as :class:`MemorySource` orders them), and its transpose, from a table of the scalar basis
    gradients per cell and point instead of a stored sparse matrix: in 3-D the matrix would be the largest array
    of a run, the table a quarter of it, for products a little over twice as slow; 2-D, where E is small and the
    steps are short, keeps the sparse matrix (docs/benchmarks/performance.md). The cells are taken in blocks of
    BLOCK (16 MB of temporaries); each component's transposed sum is a bincount over the nodes (the dof index
    arithmetic costs as much as the sum). ``E @ u`` and ``E.T @ m`` read as the matrix's do (the sums in another
    order: round-off)."""

    BLOCK = 65536

    def __init__(self, grad: np.ndarray, nodes: np.ndarray, bs: int, rows_q: np.ndarray, size_q: int, size_v: int,
                 pairs: list[tuple[int, int]]) -> None:
        # (j, cell, point, a): d_j of the element's scalar basis function a, one contiguous block per direction j
        self._grad = np.ascontiguousarray(np.moveaxis(grad, 2, 0))
        self.nodes = np.ascontiguousarray(nodes, dtype=np.int32)  # (cell, a): u's node of element node a
        self.rows_q = np.ascontiguousarray(rows_q, dtype=np.int32)  # (cell, point): the quadrature node
        self.bs, self.size_q, self.size_v, self.pairs = bs, size_q, size_v, pairs
        self.shape = (len(pairs) * size_q, size_v)
        self.T = _Transposed(self)

    @property
    def grad(self) -> np.ndarray:
        """The gradient table as (cell, point, j, a) (a view)."""
        return np.moveaxis(self._grad, 0, 2)

    def _blocks(self):
        for start in range(0, len(self.nodes), self.BLOCK):
            yield slice(start, min(start + self.BLOCK, len(self.nodes)))

    def __matmul__(self, u: np.ndarray) -> np.ndarray:
        """The components of eps(u), flat (component-major), zero at points of no cell of the rule."""
        bs, d = self.bs, self._grad.shape[0]
        out = np.zeros((len(self.pairs), self.size_q))
        columns = np.ascontiguousarray(u.reshape(-1, bs)[:, :d].T)  # (comp, node)
        for b in self._blocks():
            nodes = self.nodes[b]
            uc = [np.take(columns[i], nodes) for i in range(d)]  # (cell, a) per component
            g = [self._grad[j, b] for j in range(d)]  # (cell, point, a) per direction
            rows = self.rows_q[b]
            for c, (i, j) in enumerate(self.pairs):
                e = np.einsum("cpa,ca->cp", g[j], uc[i])
                if i != j:
                    e += np.einsum("cpa,ca->cp", g[i], uc[j])
                    e *= 0.5
                out[c, rows] = e
        return out.reshape(-1)

    def transpose_product(self, m) -> np.ndarray:
        """E^T m (m: the components, flat or (component, point); or a callable giving them at given points, asked
        block by block), into u's local array (ghosts included)."""
        bs, d = self.bs, self._grad.shape[0]
        if callable(m):
            at = m
        else:
            whole = m.reshape(len(self.pairs), self.size_q)

            def at(points: np.ndarray) -> np.ndarray:
                return whole[:, points]
        out = np.zeros((self.size_v // bs, bs))
        index = {pair: c for c, pair in enumerate(self.pairs)}
        for b in self._blocks():
            g = [self._grad[j, b] for j in range(d)]
            rows = self.rows_q[b]
            mb = at(rows.ravel()).reshape((len(self.pairs),) + rows.shape)  # (component, cell, point)
            mb[d:] *= 0.5  # d eps / d u_(a, i) = sum_j T_ij d_j phi_a, T_ii = m_ii, T_ij = T_ji = m_ij / 2
            nodes = self.nodes[b].ravel()
            for i in range(d):
                f = np.einsum("cpa,cp->ca", g[i], mb[index[(i, i)]])  # (cell, a)
                for j in range(d):
                    if j != i:
                        f += np.einsum("cpa,cp->ca", g[j], mb[index[(min(i, j), max(i, j))]])
                out[:, i] += np.bincount(nodes, f.ravel(), minlength=len(out))
        return out.reshape(-1)


def sparse_strain_operator(grad: np.ndarray, nodes: np.ndarray, bs: int, rows_q: np.ndarray, size_q: int,
                           size_v: int, pairs: list[tuple[int, int]]) -> sp.csr_matrix:
    """E as a sparse matrix (2-D; :class:`StrainMap`'s arguments): the strain components' rows, u's blocked array
    indices as columns."""
    rows, cols, vals = [], [], []
    for c, (i, j) in enumerate(pairs):
        r = (c * size_q + rows_q)[:, :, None]  # (cell, point, 1)
        # 1/2 d_j u_i + 1/2 d_i u_j; for i == j the two halves are one entry d_i u_i (0.5 g + 0.5 g == g
        # exactly), so that the COO holds no duplicates: scipy's tocsr sums duplicates in place and keeps
        # the whole unsummed buffer alive behind its slice (a third more memory for E)
        for comp, gdir, half in (((i, i, 1.0),) if i == j else ((i, j, 0.5), (j, i, 0.5))):
            v = half * grad[:, :, gdir, :]  # (cell, point, a)
            rows.append(np.broadcast_to(r, v.shape).ravel())
            cols.append(np.broadcast_to((nodes * bs + comp)[:, None, :], v.shape).ravel())
            vals.append(v.ravel())
    # rows sorted by column, as the full tensor's were (tocsr sorts them)
    return sp.coo_matrix((np.concatenate(vals), (np.concatenate(rows), np.concatenate(cols))),
                         shape=(len(pairs) * size_q, size_v)).tocsr()


class _Transposed:
    """E.T, for ``E.T @ m``."""

    def __init__(self, E: StrainMap) -> None:
        self.E = E

    def __matmul__(self, m: np.ndarray) -> np.ndarray:
        return self.E.transpose_product(m)


def strain_table(u: fem.Function, points: np.ndarray, cells: np.ndarray) -> tuple[np.ndarray, np.ndarray, int, int]:
    """What eps(u) at ``points`` (reference coordinates) of ``cells`` is made from: the scalar basis gradients there
    (cell, point, j, a), u's node of each element node (cell, a), u's block size and its local array's length (a
    vector trial function in an Expression corrupts memory in dolfinx 0.5.2: a scalar one, S and V sharing the
    element's local order). :class:`MemorySource` and the written cell stresses read their strains from it."""
    V = u.function_space
    S = fem.FunctionSpace(V.mesh, V.ufl_element().sub_elements()[0])
    ndofs = S.dofmap.dof_layout.num_dofs
    grad = fem.Expression(ufl.grad(ufl.TrialFunction(S)), points).eval(cells).reshape(len(cells), len(points), -1, ndofs)
    nodes = V.dofmap.list.array.reshape(-1, ndofs)[: len(cells)]
    bs = V.dofmap.index_map_bs
    return grad, nodes, bs, (V.dofmap.index_map.size_local + V.dofmap.index_map.num_ghosts) * bs


class MemorySource:
    """H = zeta Phi_L(A eps(u)) at the rule's points, as one product with E and a few numpy passes.

    eps(u) at the points is a fixed linear map of u's dofs: the scalar basis gradients are tabulated once (an
    Expression with a trial function) into ``strain_operator``, E, which gives the d(d+1)/2 independent components
    of the symmetric strain (xx, yy[, zz], then xy[, yz, xz]), one block of rows per component: in 2-D a sparse
    matrix (24 entries per point for P2 triangles, where the full d*d tensor took 36), in 3-D the table itself
    (:class:`StrainMap`, a quarter of the matrix's memory); both answer ``E @ u`` and ``E.T @ m``. zeta at the
    points is a second, small product. The law's numpy form (:meth:`MemoryIntegrand.compact`) acts on the compact
    components; only the result is written out in the quadrature space's d*d layout.

    The strain is linear in u, so H at an extrapolated u* = 2 u - u_prev follows from the
    strains of u and u_prev (:meth:`extrapolated`). ``keep``, set by the owner: how many of the last strains of
    the field's values are kept, each with a copy of the values it belongs to, and reused when asked for the
    same values again (an exact comparison: after a restart, or for a u that changed, they are computed again).
    1 lets the strain norm, H_33 and the next commit share u_n's strain; 2 also keeps u_{n-1}'s for the
    extrapolated trapezoid. A strain not kept is computed again: the same values, at the cost of a product.
    """

    POINTS = 65536  # points a block of H's evaluation: 3 MB of scratch in 3-D

    def __init__(self, rule: QuadratureRule, u: fem.Function, zeta, integrand: MemoryIntegrand,
                 keep: int = 0) -> None:

        d = rule.mesh.geometry.dim
        self.Q = rule.space((d, d))
        self.u, self.zeta, self.integrand, self.d = u, zeta, integrand, d
        self.keep = keep
        self._kept: tuple[np.ndarray, np.ndarray, np.ndarray] | None = None  # remember(): Phi, H, scratch
        self._cache: list[tuple[np.ndarray, np.ndarray]] = []  # (u values, their strain), the newest first
        cells = rule.cells
        npts = rule.points.shape[0]
        rows_q = self.Q.dofmap.list.array.reshape(-1, npts)[: len(cells)]  # (cell, point) -> quadrature node

        def tabulate(expr, space) -> np.ndarray:
            """Values at the points of an expression in a scalar trial function: (cell, point, comp, dof)."""
            vals = fem.Expression(expr, rule.points).eval(cells)
            return vals.reshape(len(cells), npts, -1, space.dofmap.dof_layout.num_dofs)

        size_q = self.Q.dofmap.index_map.size_local + self.Q.dofmap.index_map.num_ghosts
        self.size_q = size_q

        def nodes_of(space) -> np.ndarray:
            return space.dofmap.list.array.reshape(-1, space.dofmap.dof_layout.num_dofs)[: len(cells)]

        # eps_ij = (d_j u_i + d_i u_j) / 2 from the scalar basis gradients; columns are u's blocked array indices
        grad, nodes, bs, size_v = strain_table(u, rule.points, cells)
        self.pairs = pairs(d)
        if d == 3:  # the table, not the matrix (StrainMap: a quarter of its memory)
            self.strain_operator = StrainMap(grad, nodes, bs, rows_q, size_q, size_v, self.pairs)
        else:
            self.strain_operator = sparse_strain_operator(grad, nodes, bs, rows_q, size_q, size_v, self.pairs)
        # A eps and its trace for a block of POINTS points: H is formed block by block (no whole-mesh scratch)
        self._a = np.empty((len(self.pairs), min(size_q, self.POINTS)))
        self._extrapolated: np.ndarray | None = None  # eps(u*), made at the first extrapolation (order 2 only)
        self._trace = np.empty(self._a.shape[1])
        self.Zq = None  # zeta at the points as a sparse matrix (an element with dof transformations only)
        self._zeta_basis = None  # (point, a): zeta's basis at the points, the same on every cell
        if isinstance(zeta, fem.Function):
            Z = zeta.function_space
            self._zeta_rows, self._zeta_dofs = rows_q, nodes_of(Z)  # views of the dofmaps (no copies)
            if not Z.element.needs_dof_transformations and len(cells):  # Lagrange P1, P2
                self._zeta_basis = np.ascontiguousarray(
                    fem.Expression(ufl.TrialFunction(Z), rule.points).eval(cells[:1]).reshape(npts, -1))
            else:
                zv = tabulate(ufl.TrialFunction(Z), Z)[:, :, 0, :]  # (cell, point, a)
                r = np.broadcast_to(rows_q[:, :, None], zv.shape).ravel()
                c = np.broadcast_to(self._zeta_dofs[:, None, :], zv.shape).ravel()
                nz = Z.dofmap.index_map.size_local + Z.dofmap.index_map.num_ghosts
                self.Zq = sp.csr_matrix((zv.ravel(), (r, c)), shape=(size_q, nz))

    def forget(self) -> None:
        """Drop the kept strains (the next call computes its product: what one evaluation costs)."""
        self._cache.clear()

    def remember(self) -> None:
        """From now on keep the last Phi_L(A eps(u)) (H at zeta = 1) and H at scale 1, with copies of the u and zeta
        values they belong to, and let a call for the same values reuse them: an adaptive run's estimate forms H_n,
        and the next step's commit reads the same H_n (:meth:`unit`: the estimate's damage term reads Phi). Every
        call then forms base + scale H from H at scale 1, found or computed, so that the numbers do not depend on
        whether it was found (a restart's first commit computes it); H = zeta Phi is the product the law makes."""
        if self._kept is None:
            n = self.size_q * self.d * self.d
            self._kept = (np.empty(n), np.empty(n), np.empty(n))  # Phi, H at scale 1, scratch for scale H
            self._kept_u: np.ndarray | None = None
            self._kept_z: np.ndarray | float | None = None

    def unit(self) -> np.ndarray:
        """Phi_L(A eps(u)) at the points for the current u, in the quadrature space's layout (:meth:`remember`d
        sources only; a kept array: read it, never change it)."""
        u = self.u.x.array
        phi = self._kept[0]
        if self._kept_u is None or not _equal(self._kept_u, u):
            self._source(self.strain(), phi, 1.0, None, zeta=1.0)
            if self._kept_u is not None and self._kept_u.shape == u.shape:
                np.copyto(self._kept_u, u)
            else:
                self._kept_u = u.copy()
            self._kept_z = None
        return phi

    def _kept_h(self) -> np.ndarray:
        """H at scale 1 for the current u and zeta: the kept one, or zeta Phi (Phi found or computed) and kept."""
        phi = self.unit()
        z = self.zeta.x.array if isinstance(self.zeta, fem.Function) else float(self.zeta.value)
        held = self._kept_z
        if held is not None and (_equal(held, z) if isinstance(z, np.ndarray) else held == z):
            return self._kept[1]
        zq = self.zeta_at_points()
        d2 = self.d * self.d
        np.multiply(phi.reshape(-1, d2), zq[:, None] if isinstance(zq, np.ndarray) else zq,
                    out=self._kept[1].reshape(-1, d2))
        if isinstance(z, np.ndarray) and isinstance(held, np.ndarray) and held.shape == z.shape:
            np.copyto(held, z)
        else:
            self._kept_z = z.copy() if isinstance(z, np.ndarray) else z
        return self._kept[1]

    def strain(self, u: np.ndarray | None = None) -> np.ndarray:
        """The independent components of eps(u) at the points, (component, point); u: the field's values by default.

        Only strains of the field's own values are kept (the last ``keep`` of them, in the order computed);
        one of another array is found among them or computed. The result may be a kept array: read it,
        never change it."""
        own = u is None
        u = self.u.x.array if own else u
        found = next((eps for values, eps in self._cache if _equal(values, u)), None)  # no loop names left behind
        if found is not None:
            return found
        if self.keep and own:  # the oldest kept strain goes now, before the new one is made: never keep + 1 alive
            del self._cache[self.keep - 1:]
        eps = (self.strain_operator @ u).reshape(len(self.pairs), -1)
        if self.keep and own:
            self._cache.insert(0, (u.copy(), eps))
        return eps

    def __call__(self, out: np.ndarray | None = None, scale: float = 1.0, base: np.ndarray | None = None) -> np.ndarray:
        """out = base + scale * H at the points for the current u and zeta (base None: scale * H), in the
        quadrature space's layout (base may be out)."""
        if self._kept is None:
            return self._source(self.strain(), out, scale, base)
        h = self._kept_h()
        if out is None:
            out = np.empty_like(h)
        if base is None:
            return np.multiply(h, scale, out=out)
        return np.add(base, np.multiply(h, scale, out=self._kept[2]), out=out)

    def extrapolated(self, u_prev: np.ndarray, out: np.ndarray | None = None, scale: float = 1.0,
                     base: np.ndarray | None = None, ratio: float = 1.0) -> np.ndarray:
        """H at u* = 2 u - u_prev and the current zeta (as :meth:`__call__`): eps(u*) = 2 eps(u) - eps(u_prev),
        exactly (to round-off), from the kept strains (or a product where one is missing). ``ratio`` r of the
        steps (variable steps): u* = (1 + r) u - r u_prev."""
        if self._extrapolated is None:
            self._extrapolated = np.empty((len(self.pairs), self.size_q))
        if ratio == 1.0:
            eps = np.multiply(self.strain(), 2.0, out=self._extrapolated)
            eps -= self.strain(u_prev)
        else:
            eps = np.multiply(self.strain(), 1.0 + ratio, out=self._extrapolated)
            eps -= ratio * self.strain(u_prev)
        return self._source(eps, out, scale, base)

    def zeta_at_points(self, values: np.ndarray | None = None) -> np.ndarray | float:
        """zeta at the points (a constant zeta: its value): for a Lagrange zeta the basis at the points, tabulated
        once on one cell, applied to each cell's dofs in blocks of cells (nothing stored per point; the sums in
        another order than a sparse matrix's: round-off). ``values``: another array of zeta's space (ghosts
        included), e.g. an error of zeta, instead of zeta's own."""
        if self._zeta_basis is None:
            if self.Zq is not None:
                return self.Zq @ (self.zeta.x.array if values is None else values)
            return float(self.zeta.value)
        z = self.zeta.x.array if values is None else values
        rows, dofs, basis = self._zeta_rows, self._zeta_dofs, self._zeta_basis
        out = np.zeros(self.size_q)
        for start in range(0, len(dofs), StrainMap.BLOCK):
            b = slice(start, start + StrainMap.BLOCK)
            out[rows[b]] = np.take(z, dofs[b]) @ basis.T  # (cell, a) @ (a, point)
        return out

    def _source(self, eps: np.ndarray, out: np.ndarray | None, scale: float = 1.0,
                base: np.ndarray | None = None, zeta: np.ndarray | float | None = None) -> np.ndarray:
        """base + scale zeta Phi_L(A eps) from the compact strain, written out as the full d*d tensor, in blocks of
        POINTS points (the law acts point by point: the same values as on the whole array); ``zeta`` at the points
        (by default the field's)."""
        d = self.d
        zeta = self.zeta_at_points() if zeta is None else zeta
        if out is None:
            out = np.empty(self.size_q * d * d)
        full = out.reshape(-1, d * d)
        start = base.reshape(-1, d * d) if base is not None else None
        for first in range(0, self.size_q, self.POINTS):
            b = slice(first, min(first + self.POINTS, self.size_q))
            n = b.stop - b.start
            a = self.integrand.compact(eps[:, b], zeta[b] if isinstance(zeta, np.ndarray) else zeta, self._a[:, :n],
                                       self._trace[:n], scale)
            for c, (i, j) in enumerate(self.pairs):
                for col in (i * d + j,) if i == j else (i * d + j, j * d + i):
                    if start is None:
                        full[b, col] = a[c]
                    else:
                        np.add(start[b, col], a[c], out=full[b, col])
        return out


class PointStrainNorm:
    """||eps(u)||_L2 from the source's strain at its points: sum over points of w_q |J_K| eps : eps.

    Exact where the rule integrates eps : eps (degree >= 2 (p - 1), which the default memory rule
    2 (p - 1) + q is). The strain of u_n computed here is kept by the source (``keep`` >= 1) and
    is the one the next step's commit reads, so the norm costs one pass over the points instead
    of a product with the strain Gram matrix."""

    def __init__(self, source: MemorySource, weights: np.ndarray) -> None:
        self.source, self.weights = source, weights
        self.factors = [1.0 if i == j else 2.0 for i, j in source.pairs]  # eps_ij = eps_ji counted twice
        self.comm = source.u.function_space.mesh.comm

    def __call__(self) -> float:
        eps = self.source.strain()
        local = sum(f * float(np.dot(e * self.weights, e)) for f, e in zip(self.factors, eps))
        return math.sqrt(max(self.comm.allreduce(local, op=MPI.SUM), 0.0))


def point_weights(rule: QuadratureRule, source: MemorySource) -> np.ndarray:
    """w_q |J_K| at each point of the source's quadrature space: the rule's weight times the cell's Jacobian
    determinant on owned cells, 0 on ghost cells (their owners count them), so sums over points are integrals."""
    mesh = rule.mesh
    n_owned = mesh.topology.index_map(mesh.topology.dim).size_local
    npts = rule.points.shape[0]
    S0 = fem.FunctionSpace(mesh, ("DG", 0))
    vol = fem.petsc.assemble_vector(fem.form(ufl.TestFunction(S0) * ufl.dx))  # owned cell volumes
    cell_dofs = S0.dofmap.list.array[:n_owned]
    # |J_K| = vol_K / (reference volume), the reference volume being the sum of the weights
    weights = np.outer(vol.array_r[cell_dofs], rule.weights / rule.weights.sum())  # (owned cell, point)
    vol.destroy()
    nodes = source.Q.dofmap.list.array.reshape(-1, npts)[:n_owned]
    w = np.zeros(source.size_q)
    w[nodes.ravel()] = weights.ravel()
    return w


class MemoryForce:
    """The memory term of the residual, B M = (M, eps(w)) over the rule's points, as one product with E^T.

    Assembled, B maps the quadrature space to u's dofs with every point's d*d components, 48 entries per P2
    point, read at every step (docs/benchmarks/performance.md). It is also E^T W m: with w_q |J_K| the weight
    of each point of an owned cell (0 on ghost cells, whose owners add their part),
    (M, eps(w)) = sum_q w_q |J_K| (sum_i M_ii eps_ii(w) + sum_{i<j} (M_ij + M_ji) eps_ij(w)), so
    m holds M's diagonal components and the sums of its off-diagonal pairs (M need not be
    symmetric), and E is the source's strain operator of the independent components
    (:class:`MemorySource`), applied transposed: 24 entries per P2 point, where the full-tensor operator
    has 36 and the assembled B 48. W m is formed in m's own buffer and E^T (W m) is, in 2-D, scipy's product
    with the transposed view of E (a CSC view of the same arrays: no second operator is stored), in 3-D
    :class:`StrainMap`'s transposed product. It runs on
    the local arrays, followed by one reverse scatter. Equal to B M to round-off (tested).
    """

    def __init__(self, rule: QuadratureRule, source: MemorySource) -> None:

        self.d, self.pairs = source.d, source.pairs
        self.weights = point_weights(rule, source)
        self.strain_operator = source.strain_operator  # E (the source's own arrays)
        # 3-D: W m formed for each block of cells of StrainMap's product (no whole-mesh m); 2-D: m whole (scipy)
        self._m = None if isinstance(self.strain_operator, StrainMap) else np.empty((len(self.pairs), source.size_q))

    def weighted(self, M: fem.Function, points: np.ndarray | slice, out: np.ndarray | None = None) -> np.ndarray:
        """W m at the given points (component, point): M's diagonal components and its off-diagonal pairs' sums,
        times the points' weights."""
        d = self.d
        full = M.x.array.reshape(-1, d * d)[points]
        w = self.weights[points]
        m = np.empty((len(self.pairs), len(w))) if out is None else out
        for c, (i, j) in enumerate(self.pairs):
            if i == j:
                np.multiply(full[:, i * d + i], w, out=m[c])
            else:
                np.add(full[:, i * d + j], full[:, j * d + i], out=m[c])
                m[c] *= w
        return m

    def __call__(self, M: fem.Function, out: PETSc.Vec) -> None:
        """out = B M = E^T (W m) (owned entries; ``out`` a ghosted vector of u's space)."""
        if self._m is None:
            values = self.strain_operator.transpose_product(lambda points: self.weighted(M, points))
        else:
            values = self.strain_operator.T @ self.weighted(M, slice(None), self._m).reshape(-1)
        with out.localForm() as local:
            local.array[:] = values
        out.ghostUpdate(addv=PETSc.InsertMode.ADD, mode=PETSc.ScatterMode.REVERSE)


class OutOfPlaneSource:
    """H_33 = zeta Phi_L(lambda tr eps(u)) at the rule's points: the 33 entry of zeta Phi_L(A eps(u)) in plane strain.

    In plane strain eps_33 = 0, so (A eps)_33 = lambda (eps_11 + eps_22); Phi_L truncates
    componentwise, so the 33 entry of the truncated tensor is the truncated 33 entry.
    Uses the strain of the in-plane :class:`MemorySource` (kept there with ``keep`` >= 1, or computed again).
    """

    def __init__(self, rule: QuadratureRule, source: MemorySource) -> None:
        self.source = source
        self.Q = rule.space(())

    def __call__(self, out: np.ndarray | None = None, scale: float = 1.0, base: np.ndarray | None = None) -> np.ndarray:
        """base + scale * H_33 (as :meth:`MemorySource.__call__`)."""
        return self._source(self.source.strain(), out, scale, base)

    def extrapolated(self, u_prev: np.ndarray, out: np.ndarray | None = None, scale: float = 1.0,
                     base: np.ndarray | None = None, ratio: float = 1.0) -> np.ndarray:
        """H_33 at u* = (1 + r) u - r u_prev, r = ``ratio`` (see :meth:`MemorySource.extrapolated`)."""
        src = self.source
        eps = (1.0 + ratio) * src.strain()[:2]
        eps -= (src.strain(u_prev)[:2] if ratio == 1.0 else ratio * src.strain(u_prev)[:2])
        return self._source(eps, out, scale, base)

    def _source(self, eps: np.ndarray, out: np.ndarray | None, scale: float = 1.0,
                base: np.ndarray | None = None) -> np.ndarray:
        h = self.source.integrand.out_of_plane(eps, self.source.zeta_at_points(), scale)
        if base is not None:
            h += base
        if out is None:
            return h
        out[:] = h
        return out
