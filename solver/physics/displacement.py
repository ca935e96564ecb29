"""The fast evaluation of one time level's problem F(u) = 0, which every contact method solves (docs/model.md §3.3).

The problem itself, F(u; w) and J = dF/du in UFL, is declared in :mod:`solver.physics.level`. Here it is
evaluated through its split, where it has one (:class:`FixedSplit`):

    F(u) = K u + j(u, .) - b_n,      J = K + C(active set)

K and b_n from :mod:`operators`, j and C from :class:`contact.ContactTerm`. The implicit memory term
F_m of the trapezoidal rule (docs/model.md §3.4) adds F_m(u) to F and dF_m/du to J, and removes the split.
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
    J = K + C lives in K's own storage (one stiffness-pattern matrix, not two: memory). It relies on the split
    (:class:`FixedSplit`): only C changes with u. Off these rows J is K exactly, bit for bit; on them
    :meth:`restore` writes K's values back before the next C is added, and :meth:`mult_add` forms K x there
    from the rows kept here. A few rows: those of the cells on Gamma_C."""

    def __init__(self, K: PETSc.Mat, contact: ContactTerm, bcs) -> None:
        C = contact.C
        assemble_without_diagonal(C, contact.jacobian_form, bcs)  # C's pattern (every cell entry is inserted)
        indptr, _, _ = C.getValuesCSR()
        start, end = K.getOwnershipRange()
        rows = (start + np.flatnonzero(np.diff(indptr))).astype(PETSc.IntType)  # owned rows of C's pattern
        comm = K.getComm()
        self.rows = PETSc.IS().createGeneral(rows, comm=comm)
        self.K = K.createSubMatrix(self.rows, PETSc.IS().createStride(end - start, start, 1, comm=comm))
        self.global_rows = rows
        self._Fc = self.K.createVecLeft()
        self._scatter: PETSc.Scatter | None = None

    def restore(self, J: PETSc.Mat) -> None:
        """Put K's values back on the kept rows of J (which holds K + C there)."""
        # K's values on those rows (global columns), copied out of the kept rows for this call only: a copy kept
        # beside them held the same numbers twice (memory)
        indptr, cols, vals = self.K.getValuesCSR()
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


@dataclass(frozen=True)
class FixedSplit:
    """The capability F(u) = K u + j(u, .) - b_n with K fixed over the run (``DisplacementProblem.split``).

    What relies on it: :class:`StiffnessRows` (J = K + C in K's storage: only C changes with u); the residual
    carried between levels (K u + j(u) does not depend on the level, so F_0 = F(u_{n-1}) + b_{n-1} - b_n without
    a product or an assembly); the condensed iteration (solvers/condensed.py: K factored once, j acting on the
    contact dofs alone). The implicit memory term F_m(u) has no such split: a problem with it offers none.
    """

    K: PETSc.Mat
    contact: ContactTerm | None
    operators: Operators

    @property
    def b(self) -> PETSc.Vec:
        """b_n of the current level (the operators swap b and b_prev at each level)."""
        return self.operators.b


class DisplacementProblem:
    """Residual and Jacobian of the level's problem (declared in :mod:`solver.physics.level`), and the residual
    carried between levels.

    ``split``: the :class:`FixedSplit` the fast paths rely on, None with the implicit memory term.
    The carried residual is the problem's own contract: a method calls :meth:`level_converged` when a level
    converged (``F_last`` then holds F(u_n) for b_n, and the next level's first residual follows from it) and
    :meth:`forget_level` when it did not; ``carried`` tells which was last.
    """

    def __init__(self, u: fem.Function, ops: Operators, contact: ContactTerm | None, implicit_term=None) -> None:
        self.u, self.ops, self.contact = u, ops, contact
        self.bcs = ops.bcs
        self.level_time: float | None = None  # the time of the level begun last (begin_level)
        # F_m(u; w) (UFL), its compiled form and its Jacobian's: nonlinear in u_n, re-assembled at every evaluation
        self.implicit_memory = implicit_term(u, ops.w) if implicit_term is not None else None
        self.Fm = self.am = self.Am = None
        if self.implicit_memory is not None:
            self.Fm = fem.form(self.implicit_memory)
            self.am = fem.form(ufl.derivative(self.implicit_memory, u, ops.du))
            self.Am = ops.K.duplicate()
        self.split = FixedSplit(ops.K, contact, ops) if self.Fm is None else None
        # with the split and contact, J = K + C shares K's storage (StiffnessRows keeps K's rows under C); with the
        # implicit memory term, whose Jacobian touches every row, J is a copy of K
        self.kept = StiffnessRows(ops.K, contact, self.bcs) if contact is not None and self.split is not None else None
        self.J = ops.K.duplicate(copy=True) if self.split is None else ops.K
        # with the truncation acting, the implicit memory term's Jacobian is not symmetric
        self.symmetric = self.split is not None
        self.J.setOption(PETSc.Mat.Option.SYMMETRIC, self.symmetric)
        self.nonlinear = contact is not None or self.Fm is not None
        self.r = ops.b.duplicate()
        self.F_last = ops.b.duplicate()  # the residual at the last evaluated iterate
        self.contact_norm = 0.0  # ||j(u, .)|| at the last evaluation
        self._carried = False

    @property
    def b(self) -> PETSc.Vec:
        return self.ops.b

    # ------------------------------------------------------------------ the carried residual
    @property
    def carried(self) -> bool:
        """True when the last level converged: ``F_last`` holds F(u_{n-1}) for ``b_prev``."""
        return self._carried

    def level_converged(self) -> None:
        """The level converged at the last evaluated iterate: the next level starts from its residual."""
        self._carried = True

    def forget_level(self) -> None:
        """The level failed (or was abandoned): the next level evaluates its first residual in full."""
        self._carried = False

    def resume(self, carried: bool, contact_norm: float) -> None:
        """The carried state of a checkpointed run (``F_last`` and b restored in place by the caller)."""
        self._carried = bool(carried)
        self.contact_norm = float(contact_norm)

    # ------------------------------------------------------------------ evaluation
    def sync(self, x: PETSc.Vec) -> None:
        """Make u hold x (SNES evaluates at work vectors during line searches; the forms read u)."""
        x.ghostUpdate(addv=PETSc.InsertMode.INSERT, mode=PETSc.ScatterMode.FORWARD)
        if x.handle != self.u.vector.handle:
            x.copy(self.u.vector)
            self.u.x.scatter_forward()

    def begin_level(self, t: float) -> float:
        """Assemble b_n; return the force scale of the convergence tests: max(||b_n||, ||j(u_{n-1})||)."""
        self.level_time = t  # the level's time (a method may tell a level solved again, Heun's corrector, by it)
        self.ops.assemble_rhs(t)
        if not self._carried and self.contact is not None:
            # no carried residual (first level, or after a failure): ||j(u_{n-1})|| from a full evaluation
            self.evaluate(self.u.vector, self.r)
        return max(self.ops.b.norm(), self.contact_norm)

    def first_residual(self, F: PETSc.Vec) -> None:
        """F(u_{n-1}) for this level's b_n: with the split and a carried level, F_last + b_{n-1} - b_n."""
        if self._carried and self.split is not None:
            self.F_last.copy(F)
            F.axpy(1.0, self.ops.b_prev)
            F.axpy(-1.0, self.ops.b)
            F.copy(self.F_last)
        else:
            self.evaluate(self.u.vector, F)

    def evaluate(self, x: PETSc.Vec, F: PETSc.Vec) -> None:
        """F = F(x) = K x + j(x) + F_m(x) - b_n, with the clamped rows x - g_n (so a Newton step keeps them)."""
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
        if self.split is None:  # J = K (+ C) + dF_m/du, rebuilt at every call (it depends on zeta_n)
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
