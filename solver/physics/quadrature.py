"""Data at quadrature points: one rule for points, ``dx`` and evaluation of UFL expressions there.

The long-memory history (:mod:`solver.physics.memory`) lives in such spaces; XDMF cannot hold
them, so they are written through cell averages (:mod:`solver.io.fields`).
"""

from __future__ import annotations

import basix
import numpy as np
import ufl
from dolfinx import fem

_BASIX_CELL = {"triangle": basix.CellType.triangle, "tetrahedron": basix.CellType.tetrahedron}


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
