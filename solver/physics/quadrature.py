"""Data at quadrature points: one rule for points, ``dx`` and evaluation of UFL expressions there.

The long-memory history (:mod:`solver.physics.memory`) lives in such spaces; XDMF cannot hold
them, so they are written through cell averages (:mod:`solver.io.fields`).
"""

from __future__ import annotations

from dataclasses import dataclass

import basix
import numpy as np
import ufl
from dolfinx import fem

_BASIX_CELL = {"triangle": basix.CellType.triangle, "tetrahedron": basix.CellType.tetrahedron}


@dataclass(frozen=True)
class ContactRule:
    """The contact term's rule on each contact facet: ``points = "gauss"``, FFCx's default rule of ``degree`` (what
    ``ds(metadata={"quadrature_degree": degree})`` integrates with), or ``"nodes"``, the facet's Lagrange nodes of
    ``order`` (u's degree) with the Newton-Cotes weights: P1 the vertices with equal weights (the trapezoid rule in
    2-D, the vertex rule in 3-D), P2 in 2-D the end points and the midpoint with Simpson's 1/6, 2/3, 1/6 (the 3-point
    Gauss-Lobatto rule). With "nodes" the law acts at the nodes, one point per normal displacement dof, and the
    contact matrix is diagonal on Γ_C's nodes (lumped); ``degree`` is not read. P2 nodes on a triangle have no
    such rule with positive weights at the vertices, so "nodes" with ``order`` 2 is refused on triangular facets.

    Every consumer of the contact term's points (the UFL term, the gap field, the numpy points, the traces, the
    estimator's pressure) takes its points from here, so they agree."""

    degree: int
    points: str = "gauss"
    order: int = 1

    @classmethod
    def of(cls, cfg) -> ContactRule:
        """The rule of a scene (a :class:`~solver.config.Config`)."""
        return cls.from_solver(cfg.solver, cfg.discretization.u_degree)

    @classmethod
    def from_solver(cls, solver, u_degree: int) -> ContactRule:
        """The rule of a ``[solver]`` table (``contact_points``, ``contact_quadrature_degree``) for u of ``u_degree``
        (read by "nodes" only: every Gauss rule of a degree is one object, one gap field)."""
        return cls(solver.contact_quadrature_degree, solver.contact_points,
                   u_degree if solver.contact_points == "nodes" else 1)

    def facet_quadrature(self, facet: basix.CellType) -> tuple[np.ndarray, np.ndarray]:
        """The rule's points on the reference facet (n, fdim) and their weights (summing to its measure)."""
        if self.points == "gauss":
            return basix.make_quadrature(facet, self.degree)
        if facet == basix.CellType.interval:  # GLL with order + 1 points: the P1 and P2 nodes (0, 1 [, 1/2])
            return basix.make_quadrature(basix.QuadratureType.gll, facet, 2 * self.order - 1)
        if facet == basix.CellType.triangle and self.order == 1:
            return basix.geometry(facet)[:, :2].copy(), np.full(3, 1.0 / 6.0)
        raise ValueError(f"contact points 'nodes': no nodal rule for P{self.order} on {facet.name} facets")

    def metadata(self, facet: basix.CellType) -> dict:
        """The ``ds`` metadata of the rule (Gauss: exactly the degree's, as the term always had)."""
        if self.points == "gauss":
            return {"quadrature_degree": self.degree}
        # FFCx 0.5's "vertex" scheme takes the cell's vertices, not the facet's, for a ds: the rule is given as custom,
        # as tuples (UFL's signature takes str() of the metadata: exact for these few floats, and without its warning
        # about arrays)
        points, weights = self.facet_quadrature(facet)
        return {"quadrature_rule": "custom", "quadrature_degree": 2 * self.order - 1,
                "quadrature_points": tuple(map(tuple, points.tolist())), "quadrature_weights": tuple(weights.tolist())}


def contact_rule(rule: int | ContactRule) -> ContactRule:
    """A :class:`ContactRule` from a rule or a Gauss degree."""
    return rule if isinstance(rule, ContactRule) else ContactRule(int(rule))


def facet_type(mesh) -> basix.CellType:
    """The basix type of the mesh's facets (interval in 2-D, triangle in 3-D)."""
    return {2: basix.CellType.interval, 3: basix.CellType.triangle}[mesh.topology.dim]


def all_finite(a: np.ndarray, total: float | None = None) -> bool:
    """Whether every entry is finite: their sum (``total``, if already taken) is finite only if they all are (one
    pass, no temporary); a sum that is not (an entry that is not, or an overflow of finite ones) is settled entry by
    entry."""
    with np.errstate(over="ignore", invalid="ignore"):
        if np.isfinite(np.add.reduce(a) if total is None else total):
            return True
    return bool(np.all(np.isfinite(a)))


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
