"""The fixed operators of the displacement problem (docs/model.md §3.3), assembled once.

    K u = (A eps(u), eps(w))                    bulk stiffness, with the clamped rows as identity
    b_n = (f_n, w)_{Gamma_N} - B M_n            tractions at t_n minus the memory term

B = (S, eps(w)) maps a tensor field S in the memory's quadrature space to nodal forces;
it is assembled once, so the memory term of each level is one sparse product.
"""

from __future__ import annotations

import numpy as np
import ufl
from dolfinx import cpp, fem
from dolfinx.fem import petsc as fpetsc
from petsc4py import PETSc

from .config import BoundaryConfig, MaterialConfig
from .geometry import Geometry
from .material import elasticity, strain


def assemble_without_diagonal(M: PETSc.Mat, form, bcs) -> None:
    """M = the form, with the clamped rows and columns zero and no unit diagonal: a term to add to K,
    whose own diagonal already holds the boundary condition."""
    M.zeroEntries()
    cpp.fem.petsc.assemble_matrix(M, form, cpp.fem.pack_constants(form), cpp.fem.pack_coefficients(form), bcs)
    M.assemble()


def clamped_conditions(geo: Geometry, V: fem.FunctionSpace, clamped: tuple[BoundaryConfig, ...]) -> list:
    """u = 0 on every clamped part (one condition on the union of their dofs)."""
    fdim = geo.mesh.topology.dim - 1
    dofs = np.unique(np.concatenate(
        [fem.locate_dofs_topological(V, fdim, geo.facets(p.name)) for p in clamped]
    )).astype(np.int32)
    return [fem.dirichletbc(np.zeros(geo.mesh.geometry.dim, dtype=PETSc.ScalarType), dofs, V)]


class Operators:
    """Dirichlet conditions, K, B and the load form; ``b`` is the current right-hand side, ``b_prev`` the last one.

    ``pattern_extra`` (a bilinear UFL form in the same ``arguments``) widens K's sparsity, so that
    terms with a wider stencil (the contact Jacobian) can be added to copies of K in place.
    """

    def __init__(self, geo: Geometry, arguments: tuple, material: MaterialConfig, bcs: list,
                 tractions: tuple[BoundaryConfig, ...], history=None, pattern_extra=None) -> None:
        mesh = geo.mesh
        d = mesh.geometry.dim
        self.du, self.w = arguments  # (trial, test): shared with the other terms of the same forms
        self.bcs = bcs

        # loads: tractions (time-dependent constants on their facets); a zero term keeps the form valid without any
        self.tractions = [(p, fem.Constant(mesh, np.zeros(d, dtype=PETSc.ScalarType))) for p in tractions]
        zero = fem.Constant(mesh, np.zeros(d, dtype=PETSc.ScalarType))
        L = sum((ufl.inner(f, self.w) * geo.ds(geo.tags[p.name]) for p, f in self.tractions),
                ufl.inner(zero, self.w) * geo.ds)
        self.L = fem.form(L)
        self.history = history
        self.B = None
        if history is not None:
            self.B = fpetsc.assemble_matrix(fem.form(history.coupling(self.w)))
            self.B.assemble()

        self.bulk = ufl.inner(elasticity(strain(self.du), material.E, material.nu, material.model),
                              strain(self.w)) * ufl.dx
        pattern = self.bulk if pattern_extra is None else self.bulk + pattern_extra
        self.K = fpetsc.create_matrix(fem.form(pattern))
        fpetsc.assemble_matrix(self.K, fem.form(self.bulk), self.bcs)
        self.K.assemble()

        self.b = fpetsc.create_vector(self.L)
        self.b_prev = self.b.duplicate()
        self._work = self.b.duplicate()

    def assemble_rhs(self, t: float) -> None:
        """b_n: tractions at t minus the memory term B M_n (the previous b is kept as ``b_prev``)."""
        self.b, self.b_prev = self.b_prev, self.b
        for part, f in self.tractions:
            f.value[:] = part.traction_at(t)
        with self.b.localForm() as b:
            b.set(0.0)
        fpetsc.assemble_vector(self.b, self.L)
        self.b.ghostUpdate(addv=PETSc.InsertMode.ADD, mode=PETSc.ScatterMode.REVERSE)
        if self.B is not None:
            self.B.mult(self.history.M.vector, self._work)
            self.b.axpy(-1.0, self._work)
        fpetsc.set_bc(self.b, self.bcs)
