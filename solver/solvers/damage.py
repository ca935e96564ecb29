"""The damage equation (docs/model.md §1, §2, §3.2), a field with diffusion, one linear solve a step.

Each step is one linear solve with a matrix assembled and factored once:

    ((zeta_n - zeta_{n-1}) / k, xi) + kappa (grad zeta_n, grad xi) = (phi(eps(u_{n-1}), zeta_{n-1}), xi)

with Fremond's source phi (:mod:`solver.physics.damage`). Nodal values are clipped to [zeta*, 1]
afterwards when the scene asks for it; the number of clipped nodes is reported.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import ufl
from dolfinx import fem
from dolfinx.fem import petsc as fpetsc
from mpi4py import MPI
from petsc4py import PETSc

from solver.config import DamageConfig
from solver.errors import DamageSolveError
from solver.physics.damage import source
from solver.physics.material import strain
from solver.solvers.linear import REASONS_KSP, make_ksp

__all__ = ["Damage", "DamageSolveError", "DamageStepInfo"]


@dataclass
class DamageStepInfo:
    """What one damage step did: nodes clipped, the range before clipping, and the Krylov iterations of its
    solve (``solver.linear = "iterative"``; 0 for a direct solve)."""

    clipped: int
    raw_min: float
    raw_max: float
    krylov_iterations: int = 0


class Damage:
    """Owns zeta (P1), the factored damage matrix and the source form."""

    def __init__(self, V: fem.FunctionSpace, u: fem.Function, cfg: DamageConfig, k: float, degree: int,
                 petsc_options: tuple[tuple[str, str], ...] = (), linear: str = "auto",
                 scheme: str = "explicit", rtol: float = 1e-10) -> None:
        self.cfg = cfg
        self.V = V
        self.zeta = fem.Function(V, name="damage")
        self.zeta.x.array[:] = cfg.zeta0
        z, xi = ufl.TrialFunction(V), ufl.TestFunction(V)
        dx = ufl.dx(metadata={"quadrature_degree": degree})
        phi = source(strain(u), self.zeta, cfg)
        k_ = fem.Constant(V.mesh, PETSc.ScalarType(k))  # a constant, not a number: one compiled form for every k
        a = (z * xi + k_ * cfg.kappa * ufl.inner(ufl.grad(z), ufl.grad(xi))) * ufl.dx
        rhs = (self.zeta + k_ * phi) * xi * dx
        self.semi_implicit = scheme == "semi_implicit"
        self.cnab2 = scheme == "cnab2"
        self.k = k
        if self.cnab2:
            # second order (docs/model.md §3.7): Crank-Nicolson diffusion, Adams-Bashforth-2 source
            #   (z_n - z_{n-1}, xi) + k kappa/2 (grad(z_n + z_{n-1}), grad xi) = k (3/2 phi_{n-1} - 1/2 phi_{n-2}, xi)
            # (the first step takes phi_0 alone: a local error O(k^2), once)
            half = 0.5 * k_ * cfg.kappa
            a = (z * xi + half * ufl.inner(ufl.grad(z), ufl.grad(xi))) * ufl.dx
            rhs = phi * xi * dx  # the source, assembled each step; the rest is the matrix B zeta_{n-1}
            self.B = fpetsc.assemble_matrix(fem.form((z * xi - half * ufl.inner(ufl.grad(z), ufl.grad(xi))) * ufl.dx))
            self.B.assemble()
        if self.semi_implicit:
            # phi(zeta_n) ~ phi(zeta_{n-1}) + phi_zeta (zeta_n - zeta_{n-1}), phi_zeta = lambda1 H(zeta - zeta*) / eta^2:
            # the matrix depends on zeta_{n-1} (assembled and factored every step) and loses
            # definiteness when k phi_zeta > 1, so it is factored with LU, not Cholesky
            phi_z = ufl.conditional(ufl.gt(self.zeta, cfg.zeta_star), cfg.lambda1 / self.zeta**2, 0.0)
            a -= k_ * phi_z * z * xi * dx
            rhs -= k_ * phi_z * self.zeta * xi * dx
        self.a = fem.form(a)
        self.L = fem.form(rhs)
        self.A = fpetsc.assemble_matrix(self.a)
        self.A.assemble()
        if not self.semi_implicit:
            self.A.setOption(PETSc.Mat.Option.SPD, True)
        self.b = fpetsc.create_vector(self.L)
        self.x = self.b.duplicate()
        self.ksp = make_ksp(V.mesh.comm, self.A, "damage_", petsc_options, linear, symmetric=not self.semi_implicit,
                            rtol=rtol)
        self.nlocal = V.dofmap.index_map.size_local * V.dofmap.index_map_bs
        self.iterative = linear == "iterative"
        self._krylov = 0  # Krylov iterations of the last solve (iterative only)
        if self.cnab2:
            self.s = self.b.duplicate()  # (phi_{n-1}, xi)
            self.s_prev = self.b.duplicate()  # (phi_{n-2}, xi)
            self.have_prev = False
            self._Bz = self.b.duplicate()

    def state(self) -> dict[str, np.ndarray]:
        """Owned arrays a checkpoint must carry besides zeta (the previous source of the second-order step)."""
        return {"source_prev": self.s_prev.array} if self.cnab2 else {}

    def scalars(self) -> dict[str, float]:
        return {"have_prev": float(self.have_prev)} if self.cnab2 else {}

    def restore(self, name: str, values: np.ndarray) -> None:
        {"source_prev": self.s_prev}[name].array[:] = values.ravel()

    def restore_scalars(self, scalars: dict[str, float]) -> None:
        if self.cnab2:
            self.have_prev = bool(scalars.get("have_prev", 0.0))

    def assemble_rhs(self) -> None:
        """(zeta_{n-1} + k phi(eps(u_{n-1}), zeta_{n-1}), xi)."""
        with self.b.localForm() as b:
            b.set(0.0)
        fpetsc.assemble_vector(self.b, self.L)
        self.b.ghostUpdate(addv=PETSc.InsertMode.ADD, mode=PETSc.ScatterMode.REVERSE)
        if self.cnab2:  # b = B zeta_{n-1} + k (3/2 s_{n-1} - 1/2 s_{n-2}), with s = (phi, xi) just assembled into b
            self.b.copy(self.s)
            self.B.mult(self.zeta.vector, self._Bz)
            self.b.scale(1.5 * self.k if self.have_prev else self.k)
            if self.have_prev:
                self.b.axpy(-0.5 * self.k, self.s_prev)
            self.b.axpy(1.0, self._Bz)

    def step(self) -> DamageStepInfo:
        """Advance zeta by one step using the current u and zeta (levels n-1)."""
        if self.semi_implicit:
            # the linearised step divides by 1 - k phi_zeta (phi_zeta = lambda1 / zeta^2 above zeta*): where
            # k phi_zeta >= 1 it is meaningless (zeta jumps far outside [zeta*, 1]); refuse rather than clip it
            z = self.zeta.x.array[: self.nlocal]
            above = z > self.cfg.zeta_star
            worst = float((self.k * self.cfg.lambda1 / z[above] ** 2).max()) if above.any() else 0.0
            worst = self.V.mesh.comm.allreduce(worst, op=MPI.MAX)
            if worst >= 1.0:
                zmin = self.V.mesh.comm.allreduce(float(z.min()) if z.size else np.inf, op=MPI.MIN)
                raise DamageSolveError(
                    "SEMI_IMPLICIT_UNSTABLE",
                    f"k lambda1 / zeta^2 = {worst:.3g} >= 1, min zeta {zmin:.3g}; use "
                    "solver.damage_scheme = 'explicit' or a smaller k")
            self.A.zeroEntries()
            fpetsc.assemble_matrix(self.A, self.a)
            self.A.assemble()
        if self.cnab2 and not self.have_prev:
            self._zeta0 = self.zeta.vector.copy()  # the first step is corrected later (correct_first_step)
        self.assemble_rhs()
        self._solve()
        if self.cnab2:
            self.s.copy(self.s_prev)
            self.have_prev = True
        return self._clip()

    def correct_first_step(self) -> DamageStepInfo:
        """Heun's corrector for the second-order scheme's first step, after u_1 was predicted:
        (z_1 - z_0, xi) + k kappa/2 (grad(z_1 + z_0), grad xi) = k/2 (phi_0 + phi(u_1, z_1^pred), xi).
        AB2 has no phi_{-1}; the predictor alone would leave a local O(k^2) error at t_1."""
        with self.s.localForm() as s:
            s.set(0.0)
        fpetsc.assemble_vector(self.s, self.L)  # phi at (u_1 predicted, zeta_1 predicted)
        self.s.ghostUpdate(addv=PETSc.InsertMode.ADD, mode=PETSc.ScatterMode.REVERSE)
        self.B.mult(self._zeta0, self.b)
        self.b.axpy(0.5 * self.k, self.s)
        self.b.axpy(0.5 * self.k, self.s_prev)  # s_prev holds phi_0 (and keeps it for the next step's AB2)
        self._solve()
        self._zeta0 = None
        return self._clip()

    def _solve(self) -> None:
        self.ksp.solve(self.b, self.x)
        self._krylov = self.ksp.getIterationNumber() if self.iterative else 0
        reason = self.ksp.getConvergedReason()
        if reason < 0:
            raise DamageSolveError(str(REASONS_KSP.get(reason, reason)))
        self.x.copy(self.zeta.vector)
        self.zeta.x.scatter_forward()

    def _clip(self) -> DamageStepInfo:
        """Clip to [zeta*, 1] if the scene asks; report the range before clipping and the nodes clipped."""
        comm = self.V.mesh.comm
        owned = self.zeta.x.array[: self.nlocal]
        raw_min = comm.allreduce(float(owned.min()) if owned.size else np.inf, op=MPI.MIN)
        raw_max = comm.allreduce(float(owned.max()) if owned.size else -np.inf, op=MPI.MAX)
        clipped = 0
        if self.cfg.clip:
            lo, hi = self.cfg.zeta_star, 1.0
            clipped = comm.allreduce(int(np.count_nonzero((owned < lo) | (owned > hi))), op=MPI.SUM)
            np.clip(self.zeta.x.array, lo, hi, out=self.zeta.x.array)
        return DamageStepInfo(clipped, raw_min, raw_max, self._krylov)
