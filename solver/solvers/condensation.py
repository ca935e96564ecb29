"""The condensation of newton_condensed (docs/model.md §4): K factored once, S = P K^{-1} P^T on the contact dofs
and its Cholesky factor, and a level's u0 = K^{-1} b_n.

With c = j_B(u) the contact force on the contact dofs B, F(u) = K u + j(u) - b = 0 is u = u0 - K^{-1} P^T c
(P: the restriction to B): S is built column by column from m solves with K, and u is rebuilt from c by one more.
"""

from __future__ import annotations

import numpy as np
import scipy.linalg as sla
from dolfinx.fem import petsc as fpetsc
from mpi4py import MPI
from petsc4py import PETSc

from solver.physics.displacement import DisplacementProblem
from solver.solvers.contact_dofs import ContactDofs
from solver.solvers.linear import OwnOptions, direct_options
from solver.solvers.settings import LinearSettings


class Condensation:
    """S = P K^{-1} P^T and its Cholesky factor, K's factorization, and the level's u0 = K^{-1} b."""

    def __init__(self, problem: DisplacementProblem, dofs: ContactDofs, comm: MPI.Comm, linear: LinearSettings) -> None:
        self.problem, self.dofs = problem, dofs
        self.ksp = PETSc.KSP().create(comm)
        # options of its own, removed with it: a process that builds many models (a study, a sweep from
        # Python) would otherwise fill PETSc's options database (PETSc error 55 after some hundred)
        self.options = OwnOptions(self, "mech_condensed_", direct_options(comm, linear.kind, True), ())
        self.ksp.setOptionsPrefix(self.options.prefix)
        self.ksp.setOperators(problem.stiffness())  # K, also after Newton steps wrote K + C into its storage (auto)
        self.ksp.setFromOptions()
        # K's factorization stays K's when a later full Newton iteration (newton_energy's, where the steps through
        # K do not settle a level) adds C into the same storage: PETSc would otherwise refactor it at the next solve
        self.ksp.getPC().setReusePreconditioner(True)
        self.u0 = problem.u.vector.duplicate()
        self.u0_B = np.zeros(dofs.m)  # P u0 of the current level (all m; :meth:`level`)
        self._e = problem.u.vector.duplicate()
        self._z = problem.u.vector.duplicate()
        self.S = self._schur()
        self.chol = sla.cho_factor(self.S)

    def _schur(self) -> np.ndarray:
        """S, column by column: m solves with K (collective)."""
        dofs, e, z = self.dofs, self._e, self.u0
        rows = np.empty((len(dofs.local), dofs.m))
        for j in range(dofs.m):
            e.set(0.0)
            if dofs.offset <= j < dofs.offset + len(dofs.local):
                e.array[dofs.local[j - dofs.offset]] = 1.0
            self.ksp.solve(e, z)
            rows[:, j] = z.array_r[dofs.local]
        if dofs.comm.size == 1:
            S = rows
        else:
            S = np.vstack(dofs.comm.allgather(rows))
        return 0.5 * (S + S.T)  # symmetric up to round-off

    def level(self) -> np.ndarray:
        """u0 = K^{-1} b_n with the Dirichlet values of the level, and u0_B = P u0 (all m), returned."""
        self.ksp.solve(self.problem.ops.b, self.u0)
        fpetsc.set_bc(self.u0, self.problem.bcs)
        self.u0_B = self.dofs.gather(self.u0.array_r[self.dofs.local])
        return self.u0_B

    def rebuild(self, c: np.ndarray, x: PETSc.Vec) -> None:
        """x = u0 - K^{-1} P^T c: the displacement in equilibrium inside for the contact forces c."""
        self.u0.copy(x)
        self.add_column_solve(-c, x)

    def add_column_solve(self, c: np.ndarray, x: PETSc.Vec) -> None:
        """x += K^{-1} P^T c (one solve with K)."""
        self._e.set(0.0)
        self._e.array[self.dofs.local] = self.dofs.mine(c)
        self.ksp.solve(self._e, self._z)
        x.axpy(1.0, self._z)
