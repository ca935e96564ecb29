"""The long-memory integral, kept at quadrature points (docs/model.md §3.1, §3.4).

The scheme's memory sum is a left-rectangle rule,

    M_n = k sum_{m=0}^{n-1} g((n - m) k) H_m,    H_m = zeta_m Phi_L(A eps(u_m)),

evaluated at the quadrature points of the displacement form. For a Prony
kernel g(s) = sum_i c_i exp(-s / tau_i) (tau = inf: the constant kernel) it is
the recursion M_n^i = exp(-k / tau_i) (M_{n-1}^i + k c_i H_{n-1}): no past is
stored. Only a tabulated (general) kernel keeps every H_m.

The history is committed once per step, after the step has converged. The trapezoidal
rule (``memory.rule = "trapezoid"``) adds the current level's (k/2) g(0) H_n, implicit in
u_n: :func:`trapezoid_term` gives that term of the displacement residual. With
``trapezoid_extrapolated`` (the default of ``time.order = 2``) H_n is evaluated at
u* = 2 u_{n-1} - u_{n-2} instead (:meth:`PronyHistory.set_current`): an O(k^3) change per
level that keeps the Jacobian, and its factorization, independent of zeta_n.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import basix
import dolfinx.fem.petsc  # noqa: F401  (fem.petsc)
import numpy as np
import ufl
from dolfinx import fem
from mpi4py import MPI
from petsc4py import PETSc

from solver.config import MemoryConfig

_BASIX_CELL = {"triangle": basix.CellType.triangle, "tetrahedron": basix.CellType.tetrahedron}


def all_finite(a: np.ndarray, total: float | None = None) -> bool:
    """Whether every entry is finite: their sum (``total``, if already taken) is finite only if they all are (one
    pass, no temporary); a sum that is not (an entry that is not, or an overflow of finite ones) is settled entry by
    entry."""
    with np.errstate(over="ignore", invalid="ignore"):
        if np.isfinite(np.add.reduce(a) if total is None else total):
            return True
    return bool(np.all(np.isfinite(a)))


def _equal(a: np.ndarray, b: np.ndarray) -> bool:
    """a == b entry by entry (exact); a sample of about 64 entries first settles most unequal pairs at once."""
    stride = max(1, a.size // 64)
    return a.shape == b.shape and np.array_equal(a[::stride], b[::stride]) and np.array_equal(a, b)


class QuadratureRule:
    """One quadrature rule for all quadrature-point data: points, ``dx`` and evaluation.

    The points come from basix and match FFCx's "default" scheme of the same
    degree, so functions in these spaces can be integrated with ``self.dx``.
    """

    def __init__(self, mesh, degree: int) -> None:
        self.mesh = mesh
        self.degree = degree
        self.points, self.weights = basix.make_quadrature(_BASIX_CELL[mesh.ufl_cell().cellname()], degree)
        self.dx = ufl.Measure(
            "dx", domain=mesh, metadata={"quadrature_degree": degree, "quadrature_scheme": "default"}
        )
        imap = mesh.topology.index_map(mesh.topology.dim)
        # local and ghost cells: every process holds consistent values without a scatter
        self.cells = np.arange(imap.size_local + imap.num_ghosts, dtype=np.int32)

    def space(self, shape: tuple[int, ...] = ()) -> fem.FunctionSpace:
        cell = self.mesh.ufl_cell()
        if shape == ():
            el = ufl.FiniteElement("Quadrature", cell, self.degree, quad_scheme="default")
        elif len(shape) == 1:
            el = ufl.VectorElement("Quadrature", cell, self.degree, dim=shape[0], quad_scheme="default")
        else:
            el = ufl.TensorElement("Quadrature", cell, self.degree, shape=shape, quad_scheme="default")
        return fem.FunctionSpace(self.mesh, el)

    def evaluator(self, expr, space: fem.FunctionSpace) -> QuadratureEvaluator:
        return QuadratureEvaluator(self, expr, space)


class QuadratureEvaluator:
    """Evaluates a UFL expression at the rule's points into an array laid out like ``space``.

    The expression is compiled once; the dof permutation is computed once.
    """

    def __init__(self, rule: QuadratureRule, expr, space: fem.FunctionSpace) -> None:
        self.expression = fem.Expression(expr, rule.points)
        self.Q = space
        self.cells = rule.cells
        self.bs = space.dofmap.bs
        npts = rule.points.shape[0]
        dofs = space.dofmap.list.array.reshape(-1, npts)[: len(self.cells)]
        self.dofs = dofs.ravel()
        self.size = space.dofmap.index_map.size_local + space.dofmap.index_map.num_ghosts
        self._values = np.zeros((len(self.cells), npts * self.bs), dtype=np.float64)
        self._identity = np.array_equal(self.dofs, np.arange(len(self.dofs)))

    def __call__(self, out: np.ndarray | None = None) -> np.ndarray:
        """Evaluate into ``out`` (flat array of the space's layout) and return it."""
        self.expression.eval(self.cells, self._values)
        if out is None:
            out = np.empty(self.size * self.bs)
        if self._identity:
            out[:] = self._values.reshape(-1)
        else:
            out.reshape(-1, self.bs)[self.dofs] = self._values.reshape(-1, self.bs)
        return out


class MemorySource:
    """H = zeta Phi_L(A eps(u)) at the rule's points, as one sparse matvec and a few numpy passes.

    eps(u) at the points is a fixed linear map of u's dofs: it is tabulated once (an
    Expression with a trial function) into a sparse matrix ``E`` that gives the d(d+1)/2
    independent components of the symmetric strain (xx, yy[, zz], then xy[, yz, xz]), one
    block of rows per component: 24 entries per point for P2 triangles, where the full
    d*d tensor took 36. zeta at the points is a second, small product. A eps, the
    truncation (skipped when no value reaches L: it is then the identity) and the factor
    zeta act on the compact components; only the result is written out in the quadrature
    space's d*d layout. Equal to the UFL expression ``memory_source`` (tested), which
    remains the definition, and bit for bit equal to the full-tensor product it replaces.

    The strain is linear in u, so H at an extrapolated u* = 2 u - u_prev follows from the
    strains of u and u_prev (:meth:`extrapolated`): with ``keep`` > 0 the last ``keep``
    strains of the field's values are kept, each with a copy of the values it belongs to, and
    reused when asked for the same values again (an exact comparison: after a restart, or for
    a u that changed, they are computed again).
    """

    def __init__(self, rule: QuadratureRule, u: fem.Function, zeta, lame_lambda: float, lame_mu: float,
                 L: float, keep: int = 0) -> None:
        import scipy.sparse as sp

        d = rule.mesh.geometry.dim
        self.Q = rule.space((d, d))
        self.u, self.zeta, self.L, self.d = u, zeta, L, d
        self.lame_lambda, self.lame_mu = lame_lambda, lame_mu  # A's Lame constants (not the compliance mu)
        self.keep = keep
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

        # eps_ij = (d_j u_i + d_i u_j) / 2 from scalar P1 gradients (a vector trial function in an
        # Expression corrupts memory in dolfinx 0.5.2); columns are u's blocked array indices
        V = u.function_space
        S = fem.FunctionSpace(rule.mesh, V.ufl_element().sub_elements()[0])
        grad = tabulate(ufl.grad(ufl.TrialFunction(S)), S)  # (cell, point, j, a)
        nodes = nodes_of(V)  # (cell, a): element node a -> u's node (S and V share the element's local order)
        bs = V.dofmap.index_map_bs
        size_v = (V.dofmap.index_map.size_local + V.dofmap.index_map.num_ghosts) * bs
        self.pairs = [(i, i) for i in range(d)] + [(i, j) for i in range(d) for j in range(i + 1, d)]
        rows, cols, vals = [], [], []
        for c, (i, j) in enumerate(self.pairs):
            r = (c * size_q + rows_q)[:, :, None]  # (cell, point, 1)
            # 1/2 d_j u_i + 1/2 d_i u_j; for i == j the two halves are one entry d_i u_i (0.5 g + 0.5 g == g
            # exactly), so that the COO holds no duplicates: scipy's tocsr sums duplicates in place and keeps
            # the whole unsummed buffer alive behind its slice (a third more memory for E in 3-D)
            for comp, gdir, half in (((i, i, 1.0),) if i == j else ((i, j, 0.5), (j, i, 0.5))):
                v = half * grad[:, :, gdir, :]  # (cell, point, a)
                rows.append(np.broadcast_to(r, v.shape).ravel())
                cols.append(np.broadcast_to((nodes * bs + comp)[:, None, :], v.shape).ravel())
                vals.append(v.ravel())
        # rows sorted by column, as the full tensor's were (tocsr sorts them)
        self.E = sp.coo_matrix((np.concatenate(vals), (np.concatenate(rows), np.concatenate(cols))),
                               shape=(len(self.pairs) * size_q, size_v)).tocsr()
        self._work = np.empty((2, len(self.pairs), size_q))  # the extrapolated strain, A eps
        self._trace = np.empty(size_q)
        self.Zq = None
        if isinstance(zeta, fem.Function):
            Z = zeta.function_space
            zv = tabulate(ufl.TrialFunction(Z), Z)[:, :, 0, :]  # (cell, point, a)
            r = np.broadcast_to(rows_q[:, :, None], zv.shape).ravel()
            c = np.broadcast_to(nodes_of(Z)[:, None, :], zv.shape).ravel()
            nz = Z.dofmap.index_map.size_local + Z.dofmap.index_map.num_ghosts
            self.Zq = sp.csr_matrix((zv.ravel(), (r, c)), shape=(size_q, nz))

    def forget(self) -> None:
        """Drop the kept strains (the next call computes its product: what one evaluation costs)."""
        self._cache.clear()

    def strain(self, u: np.ndarray | None = None) -> np.ndarray:
        """The independent components of eps(u) at the points, (component, point); u: the field's values by default.

        Only strains of the field's own values are kept (the last ``keep`` of them, in the order computed);
        one of another array is found among them or computed. The result may be a kept array: read it,
        never change it."""
        own = u is None
        u = self.u.x.array if own else u
        for values, eps in self._cache:
            if _equal(values, u):
                return eps
        eps = (self.E @ u).reshape(len(self.pairs), -1)
        if self.keep and own:
            self._cache.insert(0, (u.copy(), eps))
            del self._cache[self.keep:]
        return eps

    fused = True  # takes scale and base: a history forms base + scale * H in one pass over the compact components

    def __call__(self, out: np.ndarray | None = None, scale: float = 1.0, base: np.ndarray | None = None) -> np.ndarray:
        """out = base + scale * H at the points for the current u and zeta (base None: scale * H), in the
        quadrature space's layout (base may be out)."""
        return self._source(self.strain(), out, scale, base)

    def extrapolated(self, u_prev: np.ndarray, out: np.ndarray | None = None, scale: float = 1.0,
                     base: np.ndarray | None = None) -> np.ndarray:
        """H at u* = 2 u - u_prev and the current zeta (as :meth:`__call__`): eps(u*) = 2 eps(u) - eps(u_prev),
        exactly (to round-off), from the kept strains (or a product where one is missing)."""
        eps = np.multiply(self.strain(), 2.0, out=self._work[0])
        eps -= self.strain(u_prev)
        return self._source(eps, out, scale, base)

    def zeta_at_points(self) -> np.ndarray | float:
        return self.Zq @ self.zeta.x.array if self.Zq is not None else float(self.zeta.value)

    def _source(self, eps: np.ndarray, out: np.ndarray | None, scale: float = 1.0,
                base: np.ndarray | None = None) -> np.ndarray:
        """base + scale zeta Phi_L(A eps) from the compact strain, written out as the full d*d tensor."""
        d = self.d
        a = np.multiply(eps, 2.0 * self.lame_mu, out=self._work[1])  # A eps = 2 mu eps + lambda tr(eps) I
        tr = np.add(eps[0], eps[1], out=self._trace)
        for i in range(2, d):
            tr += eps[i]
        tr *= self.lame_lambda
        a[:d] += tr
        if a.max() > self.L or a.min() < -self.L:  # the truncation acts (NaN: skipped, and kept, like clip's)
            np.clip(a, -self.L, self.L, out=a)
        z = self.zeta_at_points()
        a *= z * scale if scale != 1.0 else z
        if out is None:
            out = np.empty(self.size_q * d * d)
        full = out.reshape(-1, d * d)
        start = base.reshape(-1, d * d) if base is not None else None
        for c, (i, j) in enumerate(self.pairs):
            for col in (i * d + j,) if i == j else (i * d + j, j * d + i):
                if start is None:
                    full[:, col] = a[c]
                else:
                    np.add(start[:, col], a[c], out=full[:, col])
        return out


class PointStrainNorm:
    """||eps(u)||_L2 from the source's strain at its points: sum over points of w_q |J_K| eps : eps.

    Exact where the rule integrates eps : eps (degree >= 2 (p - 1), which the default memory rule
    2 (p - 1) + q is). The strain of u_n computed here is kept by the source (``keep`` >= 1) and
    is the one the next step's commit reads, so the norm costs one pass over the points instead
    of a product with the strain Gram matrix."""

    def __init__(self, source: MemorySource, weights: np.ndarray) -> None:
        self.source, self.weights = source, weights
        source.keep = max(source.keep, 1)
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
    """The memory term of the residual, B M = (M, eps(w)) over the rule's points, as one sparse product.

    Assembled, B maps the quadrature space to u's dofs with every point's d*d components: for
    P2 with the degree-3 rule a product with it reads 2.4 million entries per step (3.4 ms
    at n = 64, measured; a third of the step). It is also E^T W m: with w_q |J_K| the weight
    of each point of an owned cell (0 on ghost cells, whose owners add their part),
    (M, eps(w)) = sum_q w_q |J_K| (sum_i M_ii eps_ii(w) + sum_{i<j} (M_ij + M_ji) eps_ij(w)), so
    m holds M's diagonal components and the sums of its off-diagonal pairs (M need not be
    symmetric), and E is the source's strain operator of the independent components
    (:class:`MemorySource`), transposed with the weights folded in once: 24 entries per P2
    point, where the full-tensor operator has 36 and the assembled B 48. The product runs in
    scipy on the local arrays, followed by one reverse scatter. Equal to B M to round-off
    (tested).
    """

    def __init__(self, rule: QuadratureRule, source: MemorySource) -> None:
        import scipy.sparse as sp

        self.d, self.pairs = source.d, source.pairs
        self.weights = point_weights(rule, source)
        self.EW = (source.E.T @ sp.diags(np.tile(self.weights, len(self.pairs)))).tocsr()
        self._m = np.empty((len(self.pairs), source.size_q))

    def __call__(self, M: fem.Function, out: PETSc.Vec) -> None:
        """out = B M (owned entries; ``out`` a ghosted vector of u's space)."""
        d, m = self.d, self._m
        full = M.x.array.reshape(-1, d * d)
        for c, (i, j) in enumerate(self.pairs):
            if i == j:
                m[c] = full[:, i * d + i]
            else:
                np.add(full[:, i * d + j], full[:, j * d + i], out=m[c])
        with out.localForm() as local:
            local.array[:] = self.EW @ m.reshape(-1)
        out.ghostUpdate(addv=PETSc.InsertMode.ADD, mode=PETSc.ScatterMode.REVERSE)


class OutOfPlaneSource:
    """H_33 = zeta Phi_L(lambda tr eps(u)) at the rule's points: the 33 entry of zeta Phi_L(A eps(u)) in plane strain.

    In plane strain eps_33 = 0, so (A eps)_33 = lambda (eps_11 + eps_22); Phi_L truncates
    componentwise, so the 33 entry of the truncated tensor is the truncated 33 entry.
    Uses the strain of the in-plane :class:`MemorySource`, which keeps its last one for it.
    """

    def __init__(self, rule: QuadratureRule, source: MemorySource) -> None:
        self.source = source
        source.keep = max(source.keep, 1)  # the in-plane commit's strain, read again here
        self.Q = rule.space(())

    fused = True

    def __call__(self, out: np.ndarray | None = None, scale: float = 1.0, base: np.ndarray | None = None) -> np.ndarray:
        """base + scale * H_33 (as :meth:`MemorySource.__call__`)."""
        return self._source(self.source.strain(), out, scale, base)

    def extrapolated(self, u_prev: np.ndarray, out: np.ndarray | None = None, scale: float = 1.0,
                     base: np.ndarray | None = None) -> np.ndarray:
        """H_33 at u* = 2 u - u_prev (see :meth:`MemorySource.extrapolated`)."""
        src = self.source
        eps = 2.0 * src.strain()[:2]
        eps -= src.strain(u_prev)[:2]
        return self._source(eps, out, scale, base)

    def _source(self, eps: np.ndarray, out: np.ndarray | None, scale: float = 1.0,
                base: np.ndarray | None = None) -> np.ndarray:
        src = self.source
        h = eps[0] + eps[1]
        h *= src.lame_lambda
        np.clip(h, -src.L, src.L, out=h)
        z = src.zeta_at_points()
        h *= z * scale if scale != 1.0 else z
        if base is not None:
            h += base
        if out is None:
            return h
        out[:] = h
        return out


class History:
    """Base: the memory tensor M (a quadrature function) and its update after a step."""

    M: fem.Function
    extrapolated = False  # True: the current level's term is set by set_current() before the displacement solve

    def commit(self, n: int) -> None:
        """Given the converged level n (u_n, zeta_n), form M_{n+1}."""
        raise NotImplementedError

    def extrapolate(self, u_prev: np.ndarray | None) -> None:
        """The current level's term at u* = 2 u - u_prev (``extrapolated`` histories only)."""
        raise NotImplementedError

    def finite(self) -> bool:
        """Whether M holds no NaN or inf (the stepper's check after each level)."""
        return all_finite(self.M.x.array)

    def state(self) -> dict[str, np.ndarray]:
        """Arrays that define the history, M included (checkpoints write and restore them in place)."""
        raise NotImplementedError

    def coupling(self, w) -> ufl.Form:
        """(S, eps(w)) for S in M's space: assembled once, B M is the memory term of the residual."""
        return ufl.inner(ufl.TrialFunction(self.M.function_space), ufl.sym(ufl.grad(w))) * self.rule.dx


@dataclass(frozen=True)
class SumRule:
    """The quadrature in time of a Prony history M_n = k sum_m g((n-m) k) H_m (docs/model.md §3.4, §3.7).

    ``first_weight``: the weight of H_0 in the recursion (1: left rectangles; 1/2: trapezoid, whose
    current level's term (k/2) g(0) H_n is added apart). ``extrapolated``: that term is H at an
    extrapolated u* = 2 u_{n-1} - u_{n-2}, set before the displacement solve, so the recursion's
    past sum P is kept apart from M (M_n = P_n + (k/2) g(0) H(u*)); otherwise it is implicit in u_n
    (:func:`trapezoid_term`) or absent (left), and the recursion writes M itself.
    """

    name: str
    first_weight: float
    extrapolated: bool = False


LEFT = SumRule("left", 1.0)
TRAPEZOID = SumRule("trapezoid", 0.5)
TRAPEZOID_EXTRAPOLATED = SumRule("trapezoid_extrapolated", 0.5, extrapolated=True)
SUM_RULES = {r.name: r for r in (LEFT, TRAPEZOID, TRAPEZOID_EXTRAPOLATED)}
SUM_RULES["auto"] = LEFT  # a MemoryConfig made directly, not resolved by the loader: order 1's rule


class PronyHistory(History):
    """Prony series (constant kernel: one term with tau = inf), updated recursively."""

    def __init__(self, rule: QuadratureRule, source, weights, times, k: float,
                 sum_rule: SumRule = LEFT) -> None:
        self.rule = rule
        self.M = fem.Function(source.Q, name="memory")
        self.H = source
        self.sum_rule = sum_rule
        extrapolated = self.extrapolated = sum_rule.extrapolated
        self.P = np.zeros_like(self.M.x.array) if extrapolated else None
        if extrapolated:  # H(u*) from the strains of u_{n-1} and u_{n-2}, kept by the source
            if not hasattr(source, "extrapolated"):
                raise TypeError(f"the extrapolated trapezoid needs a source with extrapolated(): {type(source).__name__}")
            if hasattr(source, "keep"):
                source.keep = max(source.keep, 2)
        self._h = np.empty_like(self.M.x.array)  # H of a level, then its increment (no temporaries per step)
        self._sum: float | None = None  # the sum of M, taken where M was last written (still in cache)
        # the implicit trapezoid's weight (k/2) g(0) of the current level: 0 at level 0 (M_0 = 0), set by commit()
        self.current_weight: fem.Constant | None = None
        self.g0 = float(np.sum(weights))
        self.k = k
        taus = list(times) if times else [math.inf] * len(weights)
        self.weights = np.asarray(weights, dtype=float)
        self.decay = np.array([math.exp(-k / t) if math.isfinite(t) else 1.0 for t in taus])
        # one term: M itself is the term; several: one array per term
        self.terms = [np.zeros_like(self.M.x.array) for _ in taus] if len(taus) > 1 else None

    def commit(self, n: int) -> None:
        half = self.sum_rule.first_weight if n == 0 else 1.0
        if self.current_weight is not None:
            self.current_weight.value = 0.5 * self.k * self.g0
        if self.terms is None:
            m = self.P if self.extrapolated else self.M.x.array
            if getattr(self.H, "fused", False):  # m += k c H, added by the source in one pass
                self.H(m, scale=half * self.k * self.weights[0], base=m)
            else:
                h = self.H(self._h)
                if half != 1.0:
                    h *= half
                m += np.multiply(h, self.k * self.weights[0], out=h)
            if self.decay[0] != 1.0:
                m *= self.decay[0]
            self._written()
            return
        h = self.H(self._h)
        if half != 1.0:
            h *= half
        total = self.P if self.extrapolated else self.M.x.array
        total[:] = 0.0
        step = np.empty_like(h)
        for term, c, e in zip(self.terms, self.weights, self.decay):
            term += np.multiply(h, self.k * c, out=step)
            term *= e
            total += term
        self._written()

    def set_current(self, h: np.ndarray) -> None:
        """M_n = P_n + (k/2) g(0) h, with h = H at the extrapolated level n (``extrapolated`` only)."""
        np.multiply(h, 0.5 * self.k * self.g0, out=self.M.x.array)
        self.M.x.array[:] += self.P
        self._written()

    def extrapolate(self, u_prev: np.ndarray | None) -> None:
        """M_n = P_n + (k/2) g(0) H(u*, zeta), u* = 2 u - u_prev with u the field's values (u_{n-1}); u_prev None:
        u* = u (``extrapolated`` only). u itself is not changed."""
        if not getattr(self.H, "fused", False):
            self.set_current(self.H(self._h) if u_prev is None else self.H.extrapolated(u_prev, self._h))
            return
        M, w = self.M.x.array, 0.5 * self.k * self.g0
        if u_prev is None:
            self.H(M, scale=w, base=self.P)
        else:
            self.H.extrapolated(u_prev, M, scale=w, base=self.P)
        self._written()

    def _written(self) -> None:
        """M was just written: take its sum now, while it is in cache (``finite`` reads it)."""
        with np.errstate(over="ignore", invalid="ignore"):
            self._sum = float(np.add.reduce(self.M.x.array))

    def finite(self) -> bool:
        """Whether M holds no NaN or inf, from the sum taken when this history last wrote M. After :meth:`state`
        (a checkpoint may write M through it) M is summed again, until the next commit."""
        return all_finite(self.M.x.array, self._sum)

    def state(self) -> dict[str, np.ndarray]:
        self._sum = None  # the caller may write the arrays
        out = {"M": self.M.x.array}
        if self.P is not None:
            out["P"] = self.P
        if self.terms is not None:
            out.update({f"M{i}": t for i, t in enumerate(self.terms)})
        return out


class TabulatedHistory(History):
    """A general kernel g(s) given as a table: the full past H_0..H_{n} is kept."""

    def __init__(self, rule: QuadratureRule, source, table, k: float, steps: int) -> None:
        self.rule = rule
        self.M = fem.Function(source.Q, name="memory")
        self.H = source
        self.k = k
        self.past = np.zeros((steps + 1, self.M.x.array.size))
        s = np.array([r[0] for r in table])
        g = np.array([r[1] for r in table])
        # g((n - m) k) for lags 1..steps+1; beyond the table, the last value holds
        self.g = np.interp(k * np.arange(0, steps + 2), s, g)

    def commit(self, n: int) -> None:
        self.H(self.past[n])
        lags = self.g[n + 1 - np.arange(n + 1)]  # g((n+1-m) k), m = 0..n
        self.M.x.array[:] = self.k * (lags @ self.past[: n + 1])

    def state(self) -> dict[str, np.ndarray]:
        return {"M": self.M.x.array, "past": self.past}


class PlaneStrainHistory(History):
    """The in-plane history and the out-of-plane one M_33 (plane strain), committed and checkpointed together.

    M_33 follows the same kernel and rule as M, with H_33 (:class:`OutOfPlaneSource`) as its
    integrand; it enters no equation (sigma_33 is a reaction of the plane-strain constraint)
    and is read by the outputs: sigma_33 = lambda tr eps(u_n) + M_33,n. Everything else is
    the in-plane history's.
    """

    def __init__(self, main: History, out_of_plane: History) -> None:
        self.main, self.out_of_plane = main, out_of_plane
        self.M33 = out_of_plane.M
        self.extrapolated = main.extrapolated  # History's class default (False) would hide the main one's

    def __getattr__(self, name: str):
        return getattr(self.main, name)

    def commit(self, n: int) -> None:
        self.main.commit(n)
        self.out_of_plane.commit(n)

    def set_current(self, h: np.ndarray) -> None:
        """The extrapolated trapezoid's current term for both (H_33 evaluated at the same, extrapolated, u)."""
        self.main.set_current(h)
        self.out_of_plane.set_current(self.out_of_plane.H())

    def extrapolate(self, u_prev: np.ndarray | None) -> None:
        """The extrapolated trapezoid's current term for both, at the same u*."""
        self.main.extrapolate(u_prev)
        self.out_of_plane.extrapolate(u_prev)

    def state(self) -> dict[str, np.ndarray]:
        return {**self.main.state(), **{f"zz_{k}": v for k, v in self.out_of_plane.state().items()}}


def memory_source(u, zeta, A, L: float):
    """H = zeta Phi_L(A eps(u)): what the kernel integrates."""
    from solver.physics.material import strain, truncate

    return zeta * truncate(A(strain(u)), L)


def make_history(cfg: MemoryConfig, rule: QuadratureRule, source, k: float, steps: int) -> History | None:
    """The cheapest exact history for the kernel: None, a recursion, or the full past.

    ``source`` evaluates H at the rule's points: a :class:`MemorySource`, or any callable
    ``source(out) -> out`` with the quadrature space as ``source.Q``.
    """
    if cfg.kernel == "none":
        return None
    if cfg.kernel in ("constant", "exponential"):
        return PronyHistory(rule, source, cfg.weights, cfg.times, k, SUM_RULES[cfg.rule])
    return TabulatedHistory(rule, source, cfg.table, k, steps)


def trapezoid_term(history: PronyHistory, zeta, A, L: float):
    """(u, w) -> the trapezoid's current-level term (k/2) g(0) (zeta_n Phi_L(A eps(u_n)), eps(w)) over the rule's points."""
    from solver.physics.material import strain

    rule = history.rule
    # a constant, not a number: not compiled into the form, and 0 at level 0, where M_0 = 0 (the history's commit
    # sets it to (k/2) g(0) from level 1 on)
    history.current_weight = fem.Constant(rule.mesh, PETSc.ScalarType(0.0))

    def term(u, w):
        H = memory_source(u, zeta, A, L)
        return history.current_weight * ufl.inner(H, strain(w)) * rule.dx

    return term
