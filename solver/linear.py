"""PETSc options and factored direct solvers shared by the physics modules.

Each solver has its own options prefix (``mech_`` for the displacement SNES
and its KSP, ``damage_`` for the damage KSP) so that a scene's
``[solver.petsc_options]`` can tune one without touching the other.
"""

from __future__ import annotations

from mpi4py import MPI
from petsc4py import PETSc


def direct_options(comm: MPI.Comm, symmetric: bool = True) -> dict[str, str]:
    """A sparse direct factorization: PETSc's own in serial (fastest here), MUMPS in parallel."""
    opts = {"ksp_type": "preonly", "pc_type": "cholesky" if symmetric else "lu"}
    if comm.size == 1:
        opts["pc_factor_mat_solver_type"] = "petsc"
        opts["pc_factor_mat_ordering_type"] = "nd"
    else:
        opts["pc_factor_mat_solver_type"] = "mumps"
    return opts


def set_options(prefix: str, defaults: dict[str, str], user: tuple[tuple[str, str], ...]) -> None:
    """Write defaults under ``prefix``, then the scene's own options (full names) on top."""
    opts = PETSc.Options()
    for key, value in defaults.items():
        opts[f"{prefix}{key}"] = value
    for key, value in user:
        if key.startswith(prefix):
            opts[key.lstrip("-")] = value


def clear_options(prefix: str, keys) -> None:
    """Remove options written by :func:`set_options` (so runs in one process do not leak)."""
    opts = PETSc.Options()
    for key in keys:
        name = f"{prefix}{key}"
        if opts.hasName(name):
            opts.delValue(name)


def make_ksp(comm: MPI.Comm, A: PETSc.Mat, prefix: str, user: tuple[tuple[str, str], ...]) -> PETSc.KSP:
    """A KSP on a fixed matrix; with the default options it factors once and then only solves."""
    defaults = direct_options(comm)
    set_options(prefix, defaults, user)
    ksp = PETSc.KSP().create(comm)
    ksp.setOptionsPrefix(prefix)
    ksp.setOperators(A)
    ksp.setFromOptions()
    clear_options(prefix, defaults)
    return ksp


REASONS_KSP = {v: k for k, v in vars(PETSc.KSP.ConvergedReason).items() if isinstance(v, int)}
REASONS_SNES = {v: k for k, v in vars(PETSc.SNES.ConvergedReason).items() if isinstance(v, int)}
