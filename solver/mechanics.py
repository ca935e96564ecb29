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
from .config import Config, ConfigError
from .geometry import Geometry
from .linear import REASONS_SNES, clear_options, direct_options, set_options
from .material import elasticity, strain
from .memory import History


def _assemble_without_diagonal(M: PETSc.Mat, form, bcs) -> None:
    """M = the form, with the clamped rows and columns zero and no unit diagonal: a term to add to K,
    whose own diagonal already holds the boundary condition."""
    M.zeroEntries()
    cpp.fem.petsc.assemble_matrix(M, form, cpp.fem.pack_constants(form), cpp.fem.pack_coefficients(form), bcs)
    M.assemble()


class SolverError(RuntimeError):
    """A displacement solve did not converge; the message says why."""


@dataclass
class SolveInfo:
    """Iterations, linear solves, factorizations and final residual of one solve."""

    iterations: int
    factorizations: int
    residual: float
    reason: str
    linear_solves: int = 0


class Mechanics:
    """Owns the forms, matrices and the SNES of the displacement problem."""

    prefix = "mech_"

    def __init__(self, geo: Geometry, cfg: Config, u: fem.Function, history: History | None,
                 implicit_term=None) -> None:
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

        # right-hand side: tractions (time-dependent constants, facets only) minus B M_n,
        # with B = (S, eps(w)) over the memory's quadrature space, assembled once
        self.tractions = [(p, fem.Constant(mesh, np.zeros(d, dtype=PETSc.ScalarType))) for p in cfg.tractions]
        L = sum((ufl.inner(f, w) * geo.ds(geo.tags[p.name]) for p, f in self.tractions),
                ufl.inner(fem.Constant(mesh, np.zeros(d, dtype=PETSc.ScalarType)), w) * geo.ds)
        self.L = fem.form(L)
        self.history = history
        self.B = None
        if history is not None:
            self.B = fpetsc.assemble_matrix(fem.form(history.coupling(w)))
            self.B.assemble()

        a_bulk = ufl.inner(self.A(strain(du)), strain(w)) * ufl.dx
        # an implicit term (the trapezoidal memory's current level): nonlinear, re-assembled per evaluation
        self.Fm = self.am = None
        if implicit_term is not None:
            Fm = implicit_term(u, w)
            self.Fm, self.am = fem.form(Fm), fem.form(ufl.derivative(Fm, u, du))
        self.has_contact = bool(cfg.contact)
        deg = cfg.solver.contact_quadrature_degree
        if self.has_contact:
            Fc = contact.residual(u, w, geo, cfg.contact, deg)
            self.Fc = fem.form(Fc)
            self.ac = fem.form(ufl.derivative(Fc, u, du))
            pattern = fem.form(a_bulk + ufl.derivative(Fc, u, du))
            self.K = fpetsc.create_matrix(pattern)
            self.C = fpetsc.create_matrix(self.ac)
        else:
            self.ac = self.C = None
            self.K = fpetsc.create_matrix(fem.form(a_bulk))
        fpetsc.assemble_matrix(self.K, fem.form(a_bulk), self.bcs)
        self.K.assemble()
        self.J = self.K.duplicate(copy=True) if (self.has_contact or self.Fm is not None) else self.K
        if self.Fm is not None:
            self.Am = self.K.duplicate()
        # with the truncation acting, the implicit memory term's Jacobian is not symmetric
        self.symmetric = self.Fm is None
        self.J.setOption(PETSc.Mat.Option.SYMMETRIC, self.symmetric)

        self.b = fpetsc.create_vector(self.L)
        self.b_prev = self.b.duplicate()
        self.r = self.b.duplicate()
        self.F_last = self.b.duplicate()  # residual at the last evaluated iterate
        self._reuse = False  # F_last belongs to the converged previous level
        self._first = False
        self._c_norm = 0.0  # ||contact forces|| at the last evaluation
        self.factorizations = 0
        if self.has_contact:
            # fingerprint of C: C r for a fixed random r changes whenever C does (with probability 1);
            # a missed change could only cost Newton iterations, never accuracy (the residual decides)
            self._probe = self.C.createVecRight()
            self._probe.setRandom(PETSc.Random().create(comm=geo.comm))
            self._c_print = self.C.createVecLeft()
            self._c_last: np.ndarray | None = None
        self._setup_snes()
        # the contact term at its points (2-D): the fixed-point methods and the penetration diagnostic
        self.points = contact.ContactPoints(geo, V, cfg.contact, deg) if self.has_contact and geo.dim == 2 else None
        self.method = cfg.solver.method if self.has_contact else "newton"
        if self.method != "newton" and self.points is None:
            raise ConfigError(f"solver.method = {self.method!r}: available for 2-D meshes only; use 'newton'")
        if self.method != "newton":
            self._setup_fixed_point(a_bulk, du, w)

        # diagnostics: contact functionals on the facets; ||eps(u)||^2 = u.E u with E assembled once
        self.force_form = fem.form(contact.force(u, geo, cfg.contact, deg)) if self.has_contact else None
        self.length_form = fem.form(contact.active_length(u, geo, cfg.contact, deg)) if self.has_contact else None
        self.E = fpetsc.assemble_matrix(fem.form(ufl.inner(strain(du), strain(w)) * ufl.dx))
        self.E.assemble()

    # ------------------------------------------------------------------ SNES
    def _setup_snes(self) -> None:
        comm = self.geo.comm
        defaults = direct_options(comm, self.cfg.solver.linear, self.symmetric)
        defaults.update({
            "snes_type": "newtonls" if (self.has_contact or self.Fm is not None) else "ksponly",
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
        snes.setConvergenceTest(self._converged)
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
        if self._first and self._reuse and self.Fm is None:
            # first evaluation of a level, at u_{n-1}: K u + j(u) = b_{n-1} + F_last there, so
            # F_0 = F_last + b_{n-1} - b_n exactly, without a matvec or a contact assembly
            self._first = False
            self.F_last.copy(F)
            F.axpy(1.0, self.b_prev)
            F.axpy(-1.0, self.b)
            F.copy(self.F_last)
            return
        self._first = False
        self._sync(x)
        with F.localForm() as f:
            f.set(0.0)
        if self.has_contact:
            fpetsc.assemble_vector(F, self.Fc)
            F.ghostUpdate(addv=PETSc.InsertMode.ADD, mode=PETSc.ScatterMode.REVERSE)
            fpetsc.set_bc(F, self.bcs, scale=0.0)
            self._c_norm = F.norm()
        if self.Fm is not None:
            fpetsc.assemble_vector(F, self.Fm)
            F.ghostUpdate(addv=PETSc.InsertMode.ADD, mode=PETSc.ScatterMode.REVERSE)
        self.K.multAdd(x, F, F)
        F.axpy(-1.0, self.b)
        fpetsc.set_bc(F, self.bcs, x, -1.0)
        F.copy(self.F_last)

    def _converged(self, snes: PETSc.SNES, it: int, norms: tuple[float, float, float]) -> int:
        """||F|| <= rtol * max(||b_n||, ||j(u_{n-1})||), or ||du|| <= rtol ||u|| after a Newton step."""
        xnorm, snorm, fnorm = norms
        rtol = self.cfg.solver.rtol
        R = PETSc.SNES.ConvergedReason
        if not np.isfinite(fnorm):
            return R.DIVERGED_FNORM_NAN
        if fnorm <= rtol * self._scale:
            return R.CONVERGED_FNORM_ABS
        if it > 0 and snorm <= rtol * xnorm:
            return R.CONVERGED_SNORM_RELATIVE
        if it >= self.cfg.solver.max_it:
            return R.DIVERGED_MAX_IT
        return R.ITERATING

    def _jacobian(self, snes: PETSc.SNES, x: PETSc.Vec, J: PETSc.Mat, P: PETSc.Mat) -> None:
        if self.Fm is not None:  # J = K (+ C) + dFm/du, rebuilt at every call (it depends on zeta_n)
            self._sync(x)
            self.K.copy(self.J, structure=PETSc.Mat.Structure.SAME_NONZERO_PATTERN)
            for form, M in ((self.ac, self.C), (self.am, self.Am)):
                if M is None:
                    continue
                _assemble_without_diagonal(M, form, self.bcs)
                self.J.axpy(1.0, M, structure=PETSc.Mat.Structure.SUBSET_NONZERO_PATTERN)
            self.factorizations += 1
            return
        if not self.has_contact:
            if self.factorizations == 0:
                self.factorizations = 1
            return
        self._sync(x)
        _assemble_without_diagonal(self.C, self.ac, self.bcs)
        self.C.mult(self._probe, self._c_print)
        values = self._c_print.array_r
        changed = self._c_last is None or not np.array_equal(values, self._c_last)
        changed = self.geo.comm.allreduce(changed, op=MPI.LOR)
        if changed:
            self.K.copy(self.J, structure=PETSc.Mat.Structure.SAME_NONZERO_PATTERN)
            self.J.axpy(1.0, self.C, structure=PETSc.Mat.Structure.SUBSET_NONZERO_PATTERN)
            self._c_last = values.copy()
            self.factorizations += 1

    # ------------------------------------------------------------------ solve
    def assemble_rhs(self, t: float) -> None:
        """b_n: tractions at t minus the memory term B M_n (the previous b is kept)."""
        self.b, self.b_prev = self.b_prev, self.b
        for part, f in self.tractions:
            f.value[:] = part.traction_at(t)
        with self.b.localForm() as b:
            b.set(0.0)
        fpetsc.assemble_vector(self.b, self.L)
        self.b.ghostUpdate(addv=PETSc.InsertMode.ADD, mode=PETSc.ScatterMode.REVERSE)
        if self.B is not None:
            self.B.mult(self.history.M.vector, self.r)
            self.b.axpy(-1.0, self.r)
        fpetsc.set_bc(self.b, self.bcs)

    def solve(self, t: float) -> SolveInfo:
        """Solve for u at time t (u holds the previous level as initial guess)."""
        self.assemble_rhs(t)
        if not self._reuse and self.has_contact:
            # first level: ||j(u_0)|| for the force scale (a gap alone can load the body)
            self._first = False
            self._residual(self.snes, self.u.vector, self.r)
        # the force scale of the convergence test: loads, or the contact forces of u_{n-1}
        self._scale = max(self.b.norm(), self._c_norm)
        if self.method != "newton":
            return self._solve_fixed_point(t)
        self._first = True
        f0 = self.factorizations
        self.snes.solve(None, self.u.vector)
        self.u.x.scatter_forward()
        reason = self.snes.getConvergedReason()
        history, _ = self.snes.getConvergenceHistory()
        its = self.snes.getIterationNumber()
        if self.has_contact or self.Fm is not None:
            residual = float(history[its]) if len(history) > its else float("nan")
        else:
            self._first = False
            self._residual(self.snes, self.u.vector, self.r)
            residual = self.r.norm()
        name = REASONS_SNES.get(reason, str(reason))
        ksp_reason = self.snes.getKSP().getConvergedReason()
        tol = self.cfg.solver.rtol * self._scale
        ok = reason > 0 and ksp_reason >= 0 and np.isfinite(residual)
        if ok and not self.has_contact and self.Fm is None:
            # one exact (direct) solve of a linear problem: the residual must meet the tolerance
            ok = residual <= tol
        if not ok:
            self._reuse = False
            tail = ", ".join(f"{r:.3e}" for r in history[-5:])
            raise SolverError(
                f"displacement solve at t = {t:.6g} failed: SNES {name}, KSP reason {ksp_reason}, "
                f"{its} iterations, last residuals [{tail}] (tolerance {tol:.3e})"
            )
        self._reuse = True
        return SolveInfo(max(its, 1), self.factorizations - f0, residual, name, linear_solves=max(its, 1))

    # ------------------------------------------------------------------ fixed-point methods
    def _setup_fixed_point(self, a_bulk, du, w) -> None:
        """Fixed-point methods: a matrix factored once (K, or K + omega N^T W N for penalty-duality)."""
        from .linear import make_ksp

        pts = self.points
        if self.method == "fixed_point":
            A = self.K
        else:
            # Bermudez-Moreno: omega per contact part = penalty_duality_omega / mu, lambda = 1 / (2 omega)
            value = self.cfg.solver.penalty_duality_omega
            n = ufl.FacetNormal(self.geo.mesh)
            deg = self.cfg.solver.contact_quadrature_degree
            a_pen = fem.form(sum((value / p.mu) * ufl.dot(du, n) * ufl.dot(w, n)
                                 * self.geo.ds(self.geo.tags[p.name], metadata={"quadrature_degree": deg})
                                 for p in self.cfg.contact))
            P = fpetsc.create_matrix(a_pen)
            _assemble_without_diagonal(P, a_pen, self.bcs)
            A = self.K.duplicate(copy=True)
            A.axpy(1.0, P, structure=PETSc.Mat.Structure.SUBSET_NONZERO_PATTERN)
            self._omega = value * pts.inv_mu
            self._lam = 1.0 / (2.0 * self._omega)
            self._q = None
        self._A_fp = A
        self.ksp_fp = make_ksp(self.geo.comm, A, "mech_fp_", self.cfg.solver.petsc_options, self.cfg.solver.linear)
        self.factorizations += 1
        self._rhs = self.b.duplicate()

    def _point_forces_into(self, vec: PETSc.Vec, values: np.ndarray) -> None:
        """vec = N^T W values (assembled over ranks)."""
        with vec.localForm() as v:
            v.array[:] = self.points.forces(values)
        vec.ghostUpdate(addv=PETSc.InsertMode.ADD, mode=PETSc.ScatterMode.REVERSE)

    def _solve_fixed_point(self, t: float) -> SolveInfo:
        """Plain fixed point K u+ = b - j(u), or Bermudez-Moreno penalty-duality; residual test only.

        A small step proves nothing for a slowly contracting iteration, so only the residual
        decides. Failures are named: diverged (residual up 1e8-fold or not finite), stagnated
        (no 0.1 % progress over 20 iterations), too many iterations.
        """
        pts, x, rhs = self.points, self.u.vector, self._rhs
        tol = self.cfg.solver.rtol * self._scale
        self._first = False
        self._residual(None, x, self.r)
        history = [self.r.norm()]
        pd = self.method == "penalty_duality"
        if pd:
            r = pts.penetration(self.u.x.array)
            self._q = np.maximum(r, 0.0) * pts.inv_mu - self._omega * r  # G^omega(r) at the start
        reason, it = ("CONVERGED_FNORM_ABS" if history[0] <= tol else None), 0
        while reason is None:
            it += 1
            r = pts.penetration(self.u.x.array)
            if pd:  # A_omega u = b + N^T W (omega g - q)
                self._point_forces_into(rhs, self._q - self._omega * pts.g)
            else:  # K u = b - N^T W p(u_nu - g)
                self._point_forces_into(rhs, np.maximum(r, 0.0) * pts.inv_mu)
            rhs.aypx(-1.0, self.b)
            fpetsc.set_bc(rhs, self.bcs)
            self.ksp_fp.solve(rhs, x)
            if self.ksp_fp.getConvergedReason() < 0:
                reason = f"DIVERGED_LINEAR_SOLVE ({self.ksp_fp.getConvergedReason()})"
                break
            self.u.x.scatter_forward()
            if pd:  # q+ = Yosida approximation of G - omega I at (r + lambda q), lambda omega = 1/2
                lam, om = self._lam, self._omega
                xq = pts.penetration(self.u.x.array) + lam * self._q
                rr = np.where(xq >= 0, xq / (1 - lam * om + lam * pts.inv_mu), xq / (1 - lam * om))
                self._q = (xq - rr) / lam
            self._residual(None, x, self.r)
            fnorm = self.r.norm()
            history.append(fnorm)
            if not np.isfinite(fnorm):
                reason = "DIVERGED_FNORM_NAN"
            elif fnorm <= tol:
                reason = "CONVERGED_FNORM_ABS"
            elif fnorm > 1e8 * max(history[0], tol):
                reason = "DIVERGED_RESIDUAL_GROWTH"
            elif it >= 21 and fnorm > 0.999 * min(history[-21:-1]):
                reason = "DIVERGED_STAGNATION"
            elif it >= self.cfg.solver.max_it:
                reason = "DIVERGED_MAX_IT"
        if not reason.startswith("CONVERGED"):
            self._reuse = False
            tail = ", ".join(f"{v:.3e}" for v in history[-5:])
            raise SolverError(f"displacement solve at t = {t:.6g} failed: {self.method} {reason}, {it} iterations, "
                              f"last residuals [{tail}] (tolerance {tol:.3e})")
        self._reuse = True
        return SolveInfo(it, 0, history[-1], reason, linear_solves=it)

    def max_penetration(self) -> float:
        """Largest u_nu - g over the contact quadrature points (0 without contact, NaN in 3-D: not computed)."""
        if self.points is not None:
            return self.points.max_penetration(self.u.x.array)
        return float("nan") if self.has_contact else 0.0

    # ------------------------------------------------------------------ checkpoints
    def state(self) -> dict[str, np.ndarray]:
        """Vectors carried from one level to the next (the first residual of a level is derived from them)."""
        return {"F_last": self.F_last.array, "b": self.b.array}

    def scalars(self) -> dict[str, float]:
        return {"c_norm": self._c_norm, "reuse": float(self._reuse)}

    def restore_vector(self, name: str, values: np.ndarray) -> None:
        """Set a carried vector (owned values) from a checkpoint."""
        vec = {"F_last": self.F_last, "b": self.b}[name]
        vec.array[:] = values.ravel()

    def restore_scalars(self, scalars: dict[str, float]) -> None:
        """Continue exactly where a checkpointed run was (the Jacobian is rebuilt at the first solve)."""
        self._c_norm = float(scalars["c_norm"])
        self._reuse = bool(scalars["reuse"])

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
        """||eps(u)||_L2 = sqrt(u . E u)."""
        self.E.mult(self.u.vector, self.r)
        return float(np.sqrt(max(self.r.dot(self.u.vector), 0.0)))
