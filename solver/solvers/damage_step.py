"""The damage equation (docs/model.md §1, §2, §3.2), a field with diffusion, one linear solve a step.

Each step is one linear solve with a matrix assembled and factored once (explicit source):

    ((zeta_n - zeta_{n-1}) / k, xi) + kappa (grad zeta_n, grad xi) = (phi(eps(u_{n-1}), zeta_{n-1}), xi)

with Fremond's source phi (:class:`solver.laws.damage.FremondSource`). One class per time scheme:
:class:`ExplicitDamage` (above), :class:`SemiImplicitDamage` (the source linearised in zeta_n),
:class:`CNAB2Damage` (second order); :func:`make_damage` picks one. Nodal values are clipped to
[zeta*, 1] afterwards when the scene asks for it; the number of clipped nodes is reported.
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
from solver.physics.cell_blocks import CellBlockForm
from solver.physics.material import strain
from solver.solvers.linear import REASONS_KSP, make_ksp

__all__ = ["CNAB2Damage", "Damage", "DamageLinearSolve", "DamageSolveError", "DamageStepInfo", "ExplicitDamage",
           "SemiImplicitDamage", "make_damage"]


@dataclass
class DamageStepInfo:
    """What one damage step did: nodes clipped, the range before clipping, and the Krylov iterations of its
    solve (``solver.linear = "iterative"``; 0 for a direct solve)."""

    clipped: int
    raw_min: float
    raw_max: float
    krylov_iterations: int = 0


@dataclass(frozen=True)
class DamageLinearSolve:
    """How the damage system is solved: PETSc options (prefix ``damage_``), the linear solver kind
    (:func:`solver.solvers.linear.make_ksp`) and the Krylov tolerance."""

    petsc_options: tuple[tuple[str, str], ...] = ()
    linear: str = "auto"
    rtol: float = 1e-10


class Damage:
    """Base: owns zeta (P1 or P2: discretization.zeta_degree), the matrix A, the right-hand side b, their solve and the clip.

    A subclass gives its forms (:meth:`_forms`) and, where they differ from the explicit step's,
    how b is assembled and what a step does; checkpoint state only where it has some.
    """

    symmetric = True  # A symmetric positive definite: Cholesky / CG

    def __init__(self, V: fem.FunctionSpace, u: fem.Function, cfg: DamageConfig, k: float, degree: int,
                 solve: DamageLinearSolve = DamageLinearSolve()) -> None:
        self.cfg = cfg
        self.law = cfg.law
        self.V = V
        self.zeta = fem.Function(V, name="damage")
        self.zeta.x.array[:] = cfg.zeta0
        z, xi = ufl.TrialFunction(V), ufl.TestFunction(V)
        dx = ufl.dx(metadata={"quadrature_degree": degree})
        phi = self.law.ufl(strain(u), self.zeta)
        k_ = fem.Constant(V.mesh, PETSc.ScalarType(k))  # a constant, not a number: one compiled form for every k
        self.k, self.k_const, self.k_prev = k, k_, None
        a, rhs = self._forms(z, xi, phi, k_, dx)
        self.a = fem.form(a)
        self.rhs_form = fem.form(rhs)
        # the same form assembled a block of cells at a time (its coefficients packed a block at a time: memory)
        self.rhs_blocks = CellBlockForm(V.mesh, rhs, compiled=self.rhs_form)
        self.A = fpetsc.assemble_matrix(self.a)
        self.A.assemble()
        if self.symmetric:
            self.A.setOption(PETSc.Mat.Option.SPD, True)
        self.b = fpetsc.create_vector(self.rhs_form)
        self.x = self.b.duplicate()
        self.ksp = make_ksp(V.mesh.comm, self.A, "damage_", solve.petsc_options, solve.linear,
                            symmetric=self.symmetric, rtol=solve.rtol)
        self.nlocal = V.dofmap.index_map.size_local * V.dofmap.index_map_bs
        self.iterative = solve.linear == "iterative"
        self._krylov = 0  # Krylov iterations of the last solve (iterative only)

    def _forms(self, z, xi, phi, k_, dx) -> tuple[ufl.Form, ufl.Form]:
        """(a, L): implicit Euler diffusion, explicit source (the module's equation times k)."""
        a = (z * xi + k_ * self.cfg.kappa * ufl.inner(ufl.grad(z), ufl.grad(xi))) * ufl.dx
        rhs = (self.zeta + k_ * phi) * xi * dx
        return a, rhs

    def set_step(self, k: float, k_prev: float | None) -> None:
        """The next step goes over k = t_n - t_{n-1}; ``k_prev`` = t_{n-1} - t_{n-2} (None at n = 1). A new k
        assembles the matrices again (factored again at the next solve); the same k changes nothing."""
        self.k_prev = k_prev
        if k == self.k:
            return
        self.k = k
        self.k_const.value = k
        self._reassemble()

    def _reassemble(self) -> None:
        """A (and the scheme's other k-dependent matrices) for the current k."""
        self.A.zeroEntries()
        fpetsc.assemble_matrix(self.A, self.a)
        self.A.assemble()

    def state(self) -> dict[str, np.ndarray]:
        """Owned arrays a checkpoint must carry besides zeta (none for a one-step scheme)."""
        return {}

    def scalars(self) -> dict[str, float]:
        """Scalars a checkpoint must carry (none for a one-step scheme)."""
        return {}

    def restore_scalars(self, scalars: dict[str, float]) -> None:
        """Take back :meth:`scalars` from a checkpoint (nothing for a one-step scheme)."""

    def assemble_rhs(self) -> None:
        """b = (L, xi) at the current u and zeta (levels n-1)."""
        with self.b.localForm() as b:
            b.set(0.0)
        self.rhs_blocks.assemble(self.b)
        self.b.ghostUpdate(addv=PETSc.InsertMode.ADD, mode=PETSc.ScatterMode.REVERSE)

    def step(self) -> DamageStepInfo:
        """Advance zeta by one step using the current u and zeta (levels n-1)."""
        self.assemble_rhs()
        self._solve()
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


class ExplicitDamage(Damage):
    """The paper's step: implicit diffusion, the source at level n-1; A assembled and factored once."""


class SemiImplicitDamage(Damage):
    """The source linearised about zeta_{n-1}: phi(zeta_n) ~ phi(zeta_{n-1}) + phi_zeta (zeta_n - zeta_{n-1}),
    phi_zeta = lambda1 H(zeta - zeta*) / eta^2.

    The matrix depends on zeta_{n-1} (assembled and factored every step) and loses definiteness
    when k phi_zeta > 1, so it is factored with LU, not Cholesky.
    """

    symmetric = False

    def _forms(self, z, xi, phi, k_, dx) -> tuple[ufl.Form, ufl.Form]:
        a, rhs = super()._forms(z, xi, phi, k_, dx)
        phi_z = self.law.ufl_slope(self.zeta)
        a -= k_ * phi_z * z * xi * dx
        rhs -= k_ * phi_z * self.zeta * xi * dx
        return a, rhs

    def _reassemble(self) -> None:
        """Nothing: every step assembles A at zeta_{n-1} and the current k."""

    def step(self) -> DamageStepInfo:
        self._check_stable()
        self.A.zeroEntries()
        fpetsc.assemble_matrix(self.A, self.a)
        self.A.assemble()
        return super().step()

    def _check_stable(self) -> None:
        """The linearised step divides by 1 - k phi_zeta (phi_zeta = lambda1 / zeta^2 above zeta*): where
        k phi_zeta >= 1 it is meaningless (zeta jumps far outside [zeta*, 1]); refuse rather than clip it."""
        comm = self.V.mesh.comm
        z = self.zeta.x.array[: self.nlocal]
        worst = self.k * float(self.law.slope(z).max()) if z.size else 0.0
        worst = comm.allreduce(worst, op=MPI.MAX)
        if worst >= 1.0:
            zmin = comm.allreduce(float(z.min()) if z.size else np.inf, op=MPI.MIN)
            raise DamageSolveError(
                "SEMI_IMPLICIT_UNSTABLE",
                f"k lambda1 / zeta^2 = {worst:.3g} >= 1, min zeta {zmin:.3g}; use "
                "solver.damage_scheme = 'explicit' or a smaller k")


class CNAB2Damage(Damage):
    """Second order (docs/model.md §3.7): Crank-Nicolson diffusion, Adams-Bashforth-2 source

        (z_n - z_{n-1}, xi) + k kappa/2 (grad(z_n + z_{n-1}), grad xi) = k (3/2 phi_{n-1} - 1/2 phi_{n-2}, xi)

    The first step has no phi_{-1}: it takes phi_0 alone (a local error O(k^2)), which Heun's
    corrector (:meth:`correct_first_step`) removes once u_1 is predicted. Its checkpoint state is
    the previous source s_{n-2} and whether there is one.
    """

    def __init__(self, *args, **kwargs) -> None:
        super().__init__(*args, **kwargs)
        self.s = self.b.duplicate()  # (phi_{n-1}, xi)
        self.s_prev = self.b.duplicate()  # (phi_{n-2}, xi)
        self.have_prev = False
        self._explicit_zeta = self.b.duplicate()
        self._zeta0: PETSc.Vec | None = None  # zeta_0 during the first step (_keep_zeta0), for its corrector

    def _forms(self, z, xi, phi, k_, dx) -> tuple[ufl.Form, ufl.Form]:
        """A = M + k kappa/2 K and ``explicit_half`` = M - k kappa/2 K (assembled here); the source (phi, xi), assembled each step."""
        half = 0.5 * k_ * self.cfg.kappa
        a = (z * xi + half * ufl.inner(ufl.grad(z), ufl.grad(xi))) * ufl.dx
        rhs = phi * xi * dx  # the source; the rest is explicit_half zeta_{n-1}
        self._explicit_form = fem.form((z * xi - half * ufl.inner(ufl.grad(z), ufl.grad(xi))) * ufl.dx)
        self.explicit_half = fpetsc.assemble_matrix(self._explicit_form)
        self.explicit_half.assemble()
        return a, rhs

    def _reassemble(self) -> None:
        super()._reassemble()
        self.explicit_half.zeroEntries()
        fpetsc.assemble_matrix(self.explicit_half, self._explicit_form)
        self.explicit_half.assemble()

    def state(self) -> dict[str, np.ndarray]:
        """The previous source of the second-order step (owned part)."""
        return {"source_prev": self.s_prev.array}

    def scalars(self) -> dict[str, float]:
        return {"have_prev": float(self.have_prev)}

    def restore(self, name: str, values: np.ndarray) -> None:
        {"source_prev": self.s_prev}[name].array[:] = values.ravel()

    def restore_scalars(self, scalars: dict[str, float]) -> None:
        self.have_prev = bool(scalars.get("have_prev", 0.0))

    def assemble_rhs(self) -> None:
        """b = B zeta_{n-1} + k (3/2 s_{n-1} - 1/2 s_{n-2}), with s = (phi, xi) just assembled into b; variable steps:
        k ((1 + r/2) s_{n-1} - r/2 s_{n-2}), r = k / k_prev (docs/model.md §3.9)."""
        super().assemble_rhs()
        self.b.copy(self.s)
        self.explicit_half.mult(self.zeta.vector, self._explicit_zeta)
        r = self.k / self.k_prev if self.k_prev is not None and self.k_prev != self.k else 1.0
        self.b.scale((1.0 + 0.5 * r) * self.k if self.have_prev else self.k)
        if self.have_prev:
            self.b.axpy(-0.5 * r * self.k, self.s_prev)
        self.b.axpy(1.0, self._explicit_zeta)

    def step(self) -> DamageStepInfo:
        if not self.have_prev:
            self._keep_zeta0()
        self.assemble_rhs()
        self._solve()
        self.s.copy(self.s_prev)
        self.have_prev = True
        return self._clip()

    def _keep_zeta0(self) -> None:
        """The first step keeps zeta_0: Heun's corrector (:meth:`correct_first_step`) starts from it again."""
        self._zeta0 = self.zeta.vector.copy()

    def correct_first_step(self) -> DamageStepInfo:
        """Heun's corrector for the first step, after u_1 was predicted:
        (z_1 - z_0, xi) + k kappa/2 (grad(z_1 + z_0), grad xi) = k/2 (phi_0 + phi(u_1, z_1^pred), xi).
        AB2 has no phi_{-1}; the predictor alone would leave a local O(k^2) error at t_1."""
        if self._zeta0 is None:
            raise RuntimeError("correct_first_step follows the first step only")
        with self.s.localForm() as s:
            s.set(0.0)
        self.rhs_blocks.assemble(self.s)  # phi at (u_1 predicted, zeta_1 predicted)
        self.s.ghostUpdate(addv=PETSc.InsertMode.ADD, mode=PETSc.ScatterMode.REVERSE)
        self.explicit_half.mult(self._zeta0, self.b)
        self.b.axpy(0.5 * self.k, self.s)
        self.b.axpy(0.5 * self.k, self.s_prev)  # s_prev holds phi_0 (and keeps it for the next step's AB2)
        self._solve()
        self._zeta0 = None
        return self._clip()


SCHEMES: dict[str, type[Damage]] = {"explicit": ExplicitDamage, "semi_implicit": SemiImplicitDamage,
                                    "cnab2": CNAB2Damage}


def make_damage(scheme: str, V: fem.FunctionSpace, u: fem.Function, cfg: DamageConfig, k: float, degree: int,
                solve: DamageLinearSolve = DamageLinearSolve()) -> Damage:
    """The damage step of ``scheme`` (explicit | semi_implicit | cnab2)."""
    try:
        cls = SCHEMES[scheme]
    except KeyError:
        raise ValueError(f"unknown damage scheme {scheme!r}; one of {sorted(SCHEMES)}") from None
    return cls(V, u, cfg, k, degree, solve)
