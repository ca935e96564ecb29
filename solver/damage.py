"""The damage equation (docs/model.md §1, §2, §3.2), a P1 field with diffusion.

Each step is one linear solve with a matrix assembled and factored once:

    ((zeta_n - zeta_{n-1}) / k, xi) + kappa (grad zeta_n, grad xi) = (phi(eps(u_{n-1}), zeta_{n-1}), xi)

with Fremond's source phi. Nodal values are clipped to [zeta*, 1] afterwards
when the scene asks for it; the number of clipped nodes is reported.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import ufl
from dolfinx import fem
from dolfinx.fem import petsc as fpetsc
from mpi4py import MPI
from petsc4py import PETSc

from .config import DamageConfig
from .errors import DamageSolveError
from .linear import REASONS_KSP, make_ksp
from .material import strain

__all__ = ["Damage", "DamageSolveError", "DamageStepInfo", "eta", "psi", "source"]


def eta(zeta, zeta_star: float):
    """eta(zeta) = zeta if zeta > zeta*, zeta* otherwise."""
    return ufl.conditional(ufl.gt(zeta, zeta_star), zeta, zeta_star)


def psi(eps, q_star: float):
    """Psi_q*(u) = min(eps(u) . eps(u), q*)."""
    return ufl.min_value(ufl.inner(eps, eps), q_star)


def source(eps, zeta, cfg: DamageConfig):
    """phi(eps, zeta) = -lambda1 (1 - eta) / eta - (lambda2 Psi / 2 - lambda3)_+."""
    e = eta(zeta, cfg.zeta_star)
    return -cfg.lambda1 * (1.0 - e) / e - ufl.max_value(0.5 * cfg.lambda2 * psi(eps, cfg.q_star) - cfg.lambda3, 0.0)


@dataclass
class DamageStepInfo:
    """What one damage step did: nodes clipped, and the range before clipping."""

    clipped: int
    raw_min: float
    raw_max: float


class Damage:
    """Owns zeta (P1), the factored damage matrix and the source form."""

    def __init__(self, V: fem.FunctionSpace, u: fem.Function, cfg: DamageConfig, k: float, degree: int,
                 petsc_options: tuple[tuple[str, str], ...] = (), linear: str = "auto",
                 scheme: str = "explicit") -> None:
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
        self.k = k
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
        self.ksp = make_ksp(V.mesh.comm, self.A, "damage_", petsc_options, linear, symmetric=not self.semi_implicit)
        self.nlocal = V.dofmap.index_map.size_local * V.dofmap.index_map_bs

    def assemble_rhs(self) -> None:
        """(zeta_{n-1} + k phi(eps(u_{n-1}), zeta_{n-1}), xi)."""
        with self.b.localForm() as b:
            b.set(0.0)
        fpetsc.assemble_vector(self.b, self.L)
        self.b.ghostUpdate(addv=PETSc.InsertMode.ADD, mode=PETSc.ScatterMode.REVERSE)

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
        self.assemble_rhs()
        self.ksp.solve(self.b, self.x)
        reason = self.ksp.getConvergedReason()
        if reason < 0:
            raise DamageSolveError(str(REASONS_KSP.get(reason, reason)))
        self.x.copy(self.zeta.vector)
        self.zeta.x.scatter_forward()
        comm = self.V.mesh.comm
        owned = self.zeta.x.array[: self.nlocal]
        raw_min = comm.allreduce(float(owned.min()) if owned.size else np.inf, op=MPI.MIN)
        raw_max = comm.allreduce(float(owned.max()) if owned.size else -np.inf, op=MPI.MAX)
        clipped = 0
        if self.cfg.clip:
            lo, hi = self.cfg.zeta_star, 1.0
            clipped = comm.allreduce(int(np.count_nonzero((owned < lo) | (owned > hi))), op=MPI.SUM)
            np.clip(self.zeta.x.array, lo, hi, out=self.zeta.x.array)
        return DamageStepInfo(clipped, raw_min, raw_max)
