"""The displacement problem of one time level, solved by PETSc SNES.

    (A eps(u_n), eps(w)) + j(u_n, w) = (f_n, w)_V - (M_n, eps(w))    for all w

The bulk stiffness K is constant: it is assembled once. The residual is
F(u) = K u + j(u, .) - b_n, where b_n (tractions and memory) is assembled once
per step and j only on the contact facets. The problem is piecewise linear, so
the Jacobian J = K + C(active set) changes only when the contact active set
does: the Jacobian callback assembles the small contact matrix C and rebuilds
J only if C changed. PETSc refactors a matrix only when it was modified, so a
step with an unchanged active set costs one triangular solve pair. Without a
contact part the problem is linear and SNES runs as a single KSP solve.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import ufl
from dolfinx import cpp, fem
from dolfinx.fem import petsc as fpetsc
from mpi4py import MPI
from petsc4py import PETSc

from . import contact
from .config import Config
from .geometry import Geometry
from .linear import REASONS_SNES, clear_options, direct_options, set_options
from .material import elasticity, strain
from .memory import History


class SolverError(RuntimeError):
    """A displacement solve did not converge; the message says why."""


@dataclass
class SolveInfo:
    """Newton iterations, factorizations and final residual of one solve."""

    iterations: int
    factorizations: int
    residual: float
    reason: str


class Mechanics:
    """Owns the forms, matrices and the SNES of the displacement problem."""

    prefix = "mech_"

    def __init__(self, geo: Geometry, cfg: Config, u: fem.Function, history: History | None) -> None:
        self.geo, self.cfg, self.u = geo, cfg, u
        V = u.function_space
        mesh = geo.mesh
        d = mesh.geometry.dim
        mat = cfg.material
        self.A = lambda eps: elasticity(eps, mat.E, mat.nu, mat.model)
        du, w = ufl.TrialFunction(V), ufl.TestFunction(V)

        fdim = mesh.topology.dim - 1
        dofs = np.unique(np.concatenate(
            [fem.locate_dofs_topological(V, fdim, geo.facets(p.name)) for p in cfg.clamped]
        )).astype(np.int32)
        self.bcs = [fem.dirichletbc(np.zeros(d, dtype=PETSc.ScalarType), dofs, V)]

        # right-hand side: tractions (time-dependent constants) and memory
        self.tractions = [(p, fem.Constant(mesh, np.zeros(d, dtype=PETSc.ScalarType))) for p in cfg.tractions]
        zero = fem.Constant(mesh, np.zeros(d, dtype=PETSc.ScalarType))
        L = ufl.inner(zero, w) * ufl.dx
        for p, f in self.tractions:
            L += ufl.inner(f, w) * geo.ds(geo.tags[p.name])
        if history is not None:
            L -= history.term(w)
        self.L = fem.form(L)

        a_bulk = ufl.inner(self.A(strain(du)), strain(w)) * ufl.dx
        self.has_contact = bool(cfg.contact)
        deg = cfg.solver.contact_quadrature_degree
        if self.has_contact:
            Fc = contact.residual(u, w, geo, cfg.contact, deg)
            self.Fc = fem.form(Fc)
            self.ac = fem.form(ufl.derivative(Fc, u, du))
            pattern = fem.form(a_bulk + ufl.derivative(Fc, u, du))
            self.K = fpetsc.create_matrix(pattern)
            self.C = fpetsc.create_matrix(self.ac)
            self._c_values: np.ndarray | None = None
        else:
            self.K = fpetsc.create_matrix(fem.form(a_bulk))
        fpetsc.assemble_matrix(self.K, fem.form(a_bulk), self.bcs)
        self.K.assemble()
        self.J = self.K.duplicate(copy=True) if self.has_contact else self.K
        self.J.setOption(PETSc.Mat.Option.SYMMETRIC, True)

        self.b = fpetsc.create_vector(self.L)
        self.r = self.b.duplicate()
        self.factorizations = 0
        self._setup_snes()

        # diagnostics
        self.force_form = fem.form(contact.force(u, geo, cfg.contact, deg)) if self.has_contact else None
        self.length_form = fem.form(contact.active_length(u, geo, cfg.contact, deg)) if self.has_contact else None
        self.strain_norm_form = fem.form(ufl.inner(strain(u), strain(u)) * ufl.dx)

    # ------------------------------------------------------------------ SNES
    def _setup_snes(self) -> None:
        comm = self.geo.comm
        defaults = direct_options(comm)
        defaults.update({
            "snes_type": "newtonls" if self.has_contact else "ksponly",
            "snes_linesearch_type": "basic",
            # the penalty 1/mu makes the residual jump by ~1/mu when contact first activates:
            # not a divergence, so PETSc's residual-growth test is off (max_it still applies)
            "snes_divergence_tolerance": "-1",
        })
        set_options(self.prefix, defaults, self.cfg.solver.petsc_options)
        snes = PETSc.SNES().create(comm)
        snes.setOptionsPrefix(self.prefix)
        snes.setFunction(self._residual, self.r)
        snes.setJacobian(self._jacobian, self.J, self.J)
        # stol: with 1/mu ~ 1e10 the residual has a roundoff floor ~ eps ||J|| ||u|| that can exceed
        # rtol * (force scale); a Newton correction below rtol ||u|| then means the active set is
        # settled and the (exact, direct) linear solve has converged
        rtol = self.cfg.solver.rtol
        snes.setTolerances(rtol=rtol, atol=0.0, stol=rtol, max_it=self.cfg.solver.max_it)
        snes.setConvergenceHistory(reset=True)
        snes.setFromOptions()
        clear_options(self.prefix, defaults)
        self.snes = snes

    def _sync(self, x: PETSc.Vec) -> None:
        # SNES evaluates at work vectors (line search): the forms read u, so copy x into it
        x.ghostUpdate(addv=PETSc.InsertMode.INSERT, mode=PETSc.ScatterMode.FORWARD)
        if x.handle != self.u.vector.handle:
            x.copy(self.u.vector)
            self.u.x.scatter_forward()

    def _residual(self, snes: PETSc.SNES, x: PETSc.Vec, F: PETSc.Vec) -> None:
        self._sync(x)
        with F.localForm() as f:
            f.set(0.0)
        if self.has_contact:
            fpetsc.assemble_vector(F, self.Fc)
            F.ghostUpdate(addv=PETSc.InsertMode.ADD, mode=PETSc.ScatterMode.REVERSE)
        self.K.multAdd(x, F, F)
        F.axpy(-1.0, self.b)
        fpetsc.set_bc(F, self.bcs, x, -1.0)

    def _jacobian(self, snes: PETSc.SNES, x: PETSc.Vec, J: PETSc.Mat, P: PETSc.Mat) -> None:
        if not self.has_contact:
            if self.factorizations == 0:
                self.factorizations = 1
            return
        self._sync(x)
        self.C.zeroEntries()
        cpp.fem.petsc.assemble_matrix(
            self.C, self.ac, cpp.fem.pack_constants(self.ac), cpp.fem.pack_coefficients(self.ac), self.bcs
        )
        self.C.assemble()
        values = self.C.getValuesCSR()[2]
        changed = self._c_values is None or not np.array_equal(values, self._c_values)
        changed = self.geo.comm.allreduce(changed, op=MPI.LOR)
        if changed:
            self.K.copy(self.J, structure=PETSc.Mat.Structure.SAME_NONZERO_PATTERN)
            self.J.axpy(1.0, self.C, structure=PETSc.Mat.Structure.SUBSET_NONZERO_PATTERN)
            self._c_values = values.copy()
            self.factorizations += 1

    # ------------------------------------------------------------------ solve
    def assemble_rhs(self, t: float) -> None:
        """b_n: tractions at t and the memory term M_n."""
        for part, f in self.tractions:
            f.value[:] = part.traction_at(t)
        with self.b.localForm() as b:
            b.set(0.0)
        fpetsc.assemble_vector(self.b, self.L)
        self.b.ghostUpdate(addv=PETSc.InsertMode.ADD, mode=PETSc.ScatterMode.REVERSE)
        fpetsc.set_bc(self.b, self.bcs)

    def solve(self, t: float) -> SolveInfo:
        """Solve for u at time t (u holds the previous level as initial guess)."""
        self.assemble_rhs(t)
        # converged when ||F|| <= rtol * (force scale): the larger of the loads ||b_n|| and the
        # internal forces ||K u_{n-1}|| (a gap alone can load the body), or rtol * ||F_0||
        self.K.mult(self.u.vector, self.r)
        scale = max(self.b.norm(), self.r.norm())
        self.snes.setTolerances(atol=self.cfg.solver.rtol * scale if scale > 0 else 1e-300)
        f0 = self.factorizations
        self.snes.solve(None, self.u.vector)
        self.u.x.scatter_forward()
        reason = self.snes.getConvergedReason()
        history, _ = self.snes.getConvergenceHistory()
        its = self.snes.getIterationNumber()
        if self.has_contact:
            residual = float(history[its]) if len(history) > its else float("nan")
        else:
            self._residual(self.snes, self.u.vector, self.r)
            residual = self.r.norm()
        name = REASONS_SNES.get(reason, str(reason))
        ksp_reason = self.snes.getKSP().getConvergedReason()
        if reason <= 0 or ksp_reason < 0 or not np.isfinite(residual):
            tail = ", ".join(f"{r:.3e}" for r in history[-5:])
            raise SolverError(
                f"displacement solve at t = {t:.6g} failed: SNES {name}, KSP reason {ksp_reason}, "
                f"{its} iterations, last residuals [{tail}] (tolerance {self.snes.getTolerances()[1]:.3e})"
            )
        if not self.has_contact and residual > max(self.snes.getTolerances()[1], 1e-300) * 1e3:
            raise SolverError(f"linear displacement solve at t = {t:.6g} left residual {residual:.3e}")
        return SolveInfo(max(its, 1), self.factorizations - f0, residual, name)

    # ------------------------------------------------------------------ diagnostics
    def contact_force(self) -> float:
        if self.force_form is None:
            return 0.0
        return self.geo.comm.allreduce(fem.assemble_scalar(self.force_form), op=MPI.SUM)

    def contact_length(self) -> float:
        if self.length_form is None:
            return 0.0
        return self.geo.comm.allreduce(fem.assemble_scalar(self.length_form), op=MPI.SUM)

    def strain_norm(self) -> float:
        return float(np.sqrt(self.geo.comm.allreduce(fem.assemble_scalar(self.strain_norm_form), op=MPI.SUM)))
