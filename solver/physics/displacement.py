"""The nonlinear system of one time level, F(u) = 0, that every contact method solves (docs/model.md §3.3).

    F(u) = K u + j(u, .) [+ F_m(u)] - b_n,      J = K + C(active set) [+ dF_m/du]

K and B are fixed (:mod:`operators`), j is the contact term (:class:`contact.ContactTerm`) and
F_m the optional implicit memory term of the trapezoidal rule (docs/model.md §3.4). The
residual of the converged level is carried to the next one: there K u + j(u) is unchanged,
so F_0 = F(u_{n-1}) + b_{n-1} - b_n exactly, without a matrix product or an assembly.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import ufl
from dolfinx import fem
from dolfinx.fem import petsc as fpetsc
from petsc4py import PETSc

from solver.physics.contact import ContactTerm
from solver.physics.operators import Operators, assemble_without_diagonal


@dataclass
class SolveInfo:
    """What a method reports for one level: iterations, linear solves, factorizations, final residual, and the
    Krylov iterations of its linear solves (``solver.linear = "iterative"``; 0 for a direct solver)."""

    iterations: int
    factorizations: int
    residual: float
    reason: str
    linear_solves: int = 0
    krylov_iterations: int = 0


class StiffnessRows:
    """K's rows where the contact Jacobian C can be nonzero (its pattern's rows), kept apart so that the Jacobian
    J = K + C can live in K's own storage (issue 30: one stiffness-pattern matrix instead of two, 0.5 KB per 3-D
    dof). Off these rows J is K exactly, bit for bit; on them :meth:`restore` writes K's values back before the
    next C is added, and :meth:`mult_add` forms K x there from the rows kept here. A few rows: those of the cells
    on Gamma_C."""

    def __init__(self, K: PETSc.Mat, contact: ContactTerm, bcs) -> None:
        C = contact.C
        assemble_without_diagonal(C, contact.jacobian_form, bcs)  # C's pattern (every cell entry is inserted)
        indptr, _, _ = C.getValuesCSR()
        start, end = K.getOwnershipRange()
        rows = (start + np.flatnonzero(np.diff(indptr))).astype(PETSc.IntType)  # owned rows of C's pattern
        comm = K.getComm()
        self.rows = PETSc.IS().createGeneral(rows, comm=comm)
        self.K = K.createSubMatrix(self.rows, PETSc.IS().createStride(end - start, start, 1, comm=comm))
        self.csr = self.K.getValuesCSR()  # K's values on those rows (global columns), written back by restore
        self.global_rows = rows
        self._Fc = self.K.createVecLeft()
        self._scatter: PETSc.Scatter | None = None

    def restore(self, J: PETSc.Mat) -> None:
        """Put K's values back on the kept rows of J (which holds K + C there)."""
        indptr, cols, vals = self.csr
        J.setValuesIJV(indptr, cols, vals, addv=PETSc.InsertMode.INSERT_VALUES, rowmap=self.global_rows)
        J.assemble()

    def mult_add(self, J: PETSc.Mat, x: PETSc.Vec, F: PETSc.Vec) -> None:
        """F += K x, with J = K off the kept rows (J x there) and K's kept rows on them."""
        if self._scatter is None:
            self._scatter = PETSc.Scatter().create(F, self.rows, self._Fc, None)
        sc, Fc = self._scatter, self._Fc
        sc.scatter(F, Fc, addv=PETSc.InsertMode.INSERT_VALUES, mode=PETSc.ScatterMode.FORWARD)
        J.multAdd(x, F, F)
        self.K.multAdd(x, Fc, Fc)
        sc.scatter(Fc, F, addv=PETSc.InsertMode.INSERT_VALUES, mode=PETSc.ScatterMode.REVERSE)


class DisplacementProblem:
    """Residual and Jacobian of the level's displacement problem, and the state carried between levels.

    ``carried`` is True when ``F_last`` holds F(u_{n-1}) for ``b_prev`` (the last level converged):
    the next level's first residual then follows from it.
    """

    def __init__(self, u: fem.Function, ops: Operators, contact: ContactTerm | None, implicit_term=None) -> None:
        self.u, self.ops, self.contact = u, ops, contact
        self.bcs = ops.bcs
        self.Fm = self.am = self.Am = None
        if implicit_term is not None:  # nonlinear in u_n: re-assembled at every evaluation
            Fm = implicit_term(u, ops.w)
            self.Fm, self.am = fem.form(Fm), fem.form(ufl.derivative(Fm, u, ops.du))
            self.Am = ops.K.duplicate()
        # with contact only, J = K + C shares K's storage (StiffnessRows keeps K's rows under C); with the implicit
        # memory term, whose Jacobian touches every row, J is a copy of K
        self.kept = StiffnessRows(ops.K, contact, self.bcs) if contact is not None and self.Fm is None else None
        self.J = ops.K.duplicate(copy=True) if self.Fm is not None else ops.K
        # with the truncation acting, the implicit memory term's Jacobian is not symmetric
        self.symmetric = self.Fm is None
        self.J.setOption(PETSc.Mat.Option.SYMMETRIC, self.symmetric)
        self.nonlinear = contact is not None or self.Fm is not None
        self.r = ops.b.duplicate()
        self.F_last = ops.b.duplicate()  # the residual at the last evaluated iterate
        self.contact_norm = 0.0  # ||j(u, .)|| at the last evaluation
        self.carried = False

    @property
    def b(self) -> PETSc.Vec:
        return self.ops.b

    def sync(self, x: PETSc.Vec) -> None:
        """Make u hold x (SNES evaluates at work vectors during line searches; the forms read u)."""
        x.ghostUpdate(addv=PETSc.InsertMode.INSERT, mode=PETSc.ScatterMode.FORWARD)
        if x.handle != self.u.vector.handle:
            x.copy(self.u.vector)
            self.u.x.scatter_forward()

    def begin_level(self, t: float) -> float:
        """Assemble b_n; return the force scale of the convergence tests: max(||b_n||, ||j(u_{n-1})||)."""
        self.ops.assemble_rhs(t)
        if not self.carried and self.contact is not None:
            # no carried residual (first level, or after a failure): ||j(u_{n-1})|| from a full evaluation
            self.evaluate(self.u.vector, self.r)
        return max(self.ops.b.norm(), self.contact_norm)

    def first_residual(self, F: PETSc.Vec) -> None:
        """F(u_{n-1}) for this level's b_n: derived from the carried residual when there is one."""
        if self.carried and self.Fm is None:
            self.F_last.copy(F)
            F.axpy(1.0, self.ops.b_prev)
            F.axpy(-1.0, self.ops.b)
            F.copy(self.F_last)
        else:
            self.evaluate(self.u.vector, F)

    def evaluate(self, x: PETSc.Vec, F: PETSc.Vec) -> None:
        """F = F(x), with the clamped rows x - 0 (so a Newton step keeps them at zero)."""
        self.sync(x)
        with F.localForm() as f:
            f.set(0.0)
        if self.contact is not None:
            self.contact_norm = self.contact.add_residual(F)
        if self.Fm is not None:
            fpetsc.assemble_vector(F, self.Fm)
            F.ghostUpdate(addv=PETSc.InsertMode.ADD, mode=PETSc.ScatterMode.REVERSE)
        if self.kept is not None:
            self.kept.mult_add(self.J, x, F)
        else:
            self.ops.K.multAdd(x, F, F)
        F.axpy(-1.0, self.ops.b)
        fpetsc.set_bc(F, self.bcs, x, -1.0)
        F.copy(self.F_last)

    def stiffness(self) -> PETSc.Mat:
        """K itself, for a method that factors it: where J = K + C lives in K's storage and a Jacobian was
        assembled there, K's rows are put back (StiffnessRows) and the next Jacobian is assembled anew."""
        if self.kept is not None and self.contact.fingerprint():
            self.kept.restore(self.J)
            self.contact.forget()
        return self.ops.K

    def update_jacobian(self, x: PETSc.Vec) -> bool:
        """Bring J to the Jacobian at x; True if J was modified (a direct solver then refactors)."""
        if self.Fm is not None:  # J = K (+ C) + dF_m/du, rebuilt at every call (it depends on zeta_n)
            self.sync(x)
            self.ops.K.copy(self.J, structure=PETSc.Mat.Structure.SAME_NONZERO_PATTERN)
            if self.contact is not None:
                self.contact.assemble_jacobian()
                self.J.axpy(1.0, self.contact.C, structure=PETSc.Mat.Structure.SUBSET_NONZERO_PATTERN)
            assemble_without_diagonal(self.Am, self.am, self.bcs)
            self.J.axpy(1.0, self.Am, structure=PETSc.Mat.Structure.SUBSET_NONZERO_PATTERN)
            return True
        if self.contact is None:
            return False
        self.sync(x)
        if not self.contact.assemble_jacobian():
            return False
        self.kept.restore(self.J)
        self.J.axpy(1.0, self.contact.C, structure=PETSc.Mat.Structure.SUBSET_NONZERO_PATTERN)
        return True
