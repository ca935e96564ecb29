"""PETSc options and factored direct solvers shared by the physics modules.

Each solver has its own options prefix (``mech_`` for the displacement SNES
and its KSP, ``damage_`` for the damage KSP) so that a scene's
``[solver.petsc_options]`` can tune one without touching the other.
"""

from __future__ import annotations

from mpi4py import MPI
from petsc4py import PETSc

from .errors import ConfigError


def direct_options(comm: MPI.Comm, kind: str = "auto", symmetric: bool = True) -> dict[str, str]:
    """A sparse Cholesky factorization of an SPD matrix, factored once and reused.

    ``petsc``: PETSc's sequential Cholesky with nested dissection (one process only);
    ``redundant``: every rank holds the whole matrix and solves it with ``petsc``;
    ``mumps``: MUMPS's distributed Cholesky. ``auto`` picks ``petsc`` on one process,
    ``redundant`` on up to 4 and ``mumps`` beyond. Measured here (n = 256, 2 ranks, see
    benchmarks): a MUMPS triangular solve costs 27 ms against 14-18 ms for the sequential
    one, so on a few ranks it is faster to solve redundantly and share the rest of the work.
    """
    if kind == "auto":
        kind = "petsc" if comm.size == 1 else "redundant" if comm.size <= 4 else "mumps"
    if kind == "petsc" and comm.size > 1:
        kind = "redundant"
    factor = "cholesky" if symmetric else "lu"
    seq = {"pc_type": factor, "pc_factor_mat_solver_type": "petsc", "pc_factor_mat_ordering_type": "nd"}
    if kind == "petsc":
        return {"ksp_type": "preonly", **seq}
    if kind == "redundant":
        opts = {"ksp_type": "preonly", "pc_type": "redundant", "pc_redundant_number": str(comm.size)}
        opts.update({f"redundant_{k}": v for k, v in seq.items()})
        return opts
    return {"ksp_type": "preonly", "pc_type": factor, "pc_factor_mat_solver_type": "mumps"}


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


def check_options(comm: MPI.Comm, prefix: str, defaults: dict[str, str], user: tuple[tuple[str, str], ...],
                  snes: bool = False) -> None:
    """Raise a ConfigError naming the scene's option under ``prefix`` that PETSc rejects (an unknown
    type, a value of the wrong kind, a factorization package that is not there).

    The options are tried on a small stand-in: a KSP (or SNES) with the same prefix on a diagonal
    matrix, set up so that the preconditioner's factorization is created. The culprit is found by
    trying the scene's options one at a time.
    """
    mine = tuple((k, v) for k, v in user if k.lstrip("-").startswith(prefix))
    if not mine:
        return
    reason = _probe(comm, prefix, defaults, mine, snes)
    if reason is None:
        return
    for key, value in mine:
        alone = _probe(comm, prefix, defaults, ((key, value),), snes)
        if alone is not None:
            raise ConfigError(key=f"solver.petsc_options.{key}", value=value, allowed=f"PETSc rejects it: {alone}")
    raise ConfigError(key="solver.petsc_options", value=dict(mine), allowed=f"PETSc rejects them together: {reason}")


def _probe(comm: MPI.Comm, prefix: str, defaults: dict[str, str], user: tuple[tuple[str, str], ...],
           snes: bool) -> str | None:
    """None if PETSc accepts the options on a stand-in problem, else the last line of its error."""
    set_options(prefix, defaults, user)
    A = PETSc.Mat().createAIJ(((1, None), (1, None)), nnz=(1, 0), comm=comm)
    start, _ = A.getOwnershipRange()
    A.setValue(start, start, 1.0)
    A.assemble()
    obj = ksp = None
    try:
        if snes:
            obj = PETSc.SNES().create(comm)
            obj.setOptionsPrefix(prefix)
            obj.setFromOptions()
            ksp = obj.getKSP()
        else:
            obj = ksp = PETSc.KSP().create(comm)
            ksp.setOptionsPrefix(prefix)
        ksp.setOperators(A)
        ksp.setFromOptions()
        ksp.setUp()
        return None
    except PETSc.Error as exc:
        lines = [ln.strip() for ln in str(exc).splitlines() if ln.strip()]
        return lines[-1].removeprefix("[0] ") if lines else f"error code {exc.ierr}"
    finally:
        if obj is not None:
            obj.destroy()
        A.destroy()
        clear_options(prefix, defaults)
        clear_options("", [k.lstrip("-") for k, _ in user])


def make_ksp(comm: MPI.Comm, A: PETSc.Mat, prefix: str, user: tuple[tuple[str, str], ...],
             kind: str = "auto", symmetric: bool = True) -> PETSc.KSP:
    """A KSP on a matrix; with the default options it factors once, and again only if A changes.
    Options PETSc rejects raise a ConfigError first (:func:`check_options`)."""
    defaults = direct_options(comm, kind, symmetric)
    check_options(comm, prefix, defaults, user)
    set_options(prefix, defaults, user)
    ksp = PETSc.KSP().create(comm)
    ksp.setOptionsPrefix(prefix)
    ksp.setOperators(A)
    ksp.setFromOptions()
    clear_options(prefix, defaults)
    return ksp


REASONS_KSP = {v: k for k, v in vars(PETSc.KSP.ConvergedReason).items() if isinstance(v, int)}
REASONS_SNES = {v: k for k, v in vars(PETSc.SNES.ConvergedReason).items() if isinstance(v, int)}
