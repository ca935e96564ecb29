"""Shared fixtures. Tests run serially and under ``mpirun -n 2`` (those not marked serial)."""

from __future__ import annotations

import contextlib
import gc
import os
import subprocess
import sys
from pathlib import Path


def _scrub_inherited_mpi_environment() -> None:
    """pytest-xdist's workers (``make test`` runs them) are started by a process whose MPI is already initialised as a
    singleton, which exports its launch variables (OMPI_MCA_ess=singleton, PMIX_NAMESPACE, ...): inherited, they make
    every ``mpirun`` a test starts fail at once with no message. The controller records the OMPI_/PMIX_ variables the
    user had; a worker drops the others before its own MPI starts."""
    mine = [k for k in os.environ if k.startswith(("OMPI_", "PMIX_"))]
    if "PYTEST_XDIST_WORKER" not in os.environ:
        os.environ.setdefault("CAMPO_TEST_MPI_VARIABLES", ",".join(mine))
        return
    kept = set(os.environ.get("CAMPO_TEST_MPI_VARIABLES", "").split(","))
    for key in mine:
        if key not in kept:
            del os.environ[key]


_scrub_inherited_mpi_environment()

import faults  # noqa: E402
import numpy as np  # noqa: E402
import pytest  # noqa: E402
from mpi4py import MPI  # noqa: E402

ROOT = Path(__file__).resolve().parents[1]

from solver.run import formcache  # noqa: E402

formcache.install()  # tests build many models per process: keep compiled forms in memory


@pytest.fixture
def comm() -> MPI.Comm:
    return MPI.COMM_WORLD


@pytest.fixture
def shared_tmp(tmp_path_factory, comm) -> Path:
    """A temporary directory made on rank 0 and shared by all ranks."""
    path = str(tmp_path_factory.mktemp("run")) if comm.rank == 0 else None
    return Path(comm.bcast(path, root=0))


@pytest.fixture(autouse=True)
def _collect(comm):
    yield
    gc.collect()
    comm.barrier()


def solve(cfg, comm, outdir=None, **kwargs):
    """Build a scene's model and run it: (model, rows)."""
    from solver.io.results import run
    from solver.run.model import build_model

    model = build_model(cfg, comm)
    return model, run(model, outdir, **kwargs)


def point_value(f, point) -> np.ndarray:
    """Value of a dolfinx Function at a physical point, the same on every rank."""
    from dolfinx import geometry

    mesh = f.function_space.mesh
    comm = mesh.comm
    p = np.zeros((1, 3))
    p[0, : len(point)] = point
    tree = geometry.BoundingBoxTree(mesh, mesh.topology.dim)
    cells = geometry.compute_colliding_cells(mesh, geometry.compute_collisions(tree, p), p).links(0)
    val = f.eval(p, cells[:1]) if len(cells) else None
    found = [v for v in comm.allgather(val) if v is not None]
    if not found:
        raise ValueError(f"point {point} is outside the mesh")
    return found[0]


def contact_residuals(model, forces: np.ndarray):
    """(F, G): the model's contact residual assembled from its UFL form, and the nodal forces ``forces`` (local
    array, e.g. ContactPoints.forces(p)) as a vector of the same layout; both summed over ghosts."""
    from dolfinx.fem import petsc as fpetsc
    from petsc4py import PETSc

    F = model.mech.ops.b.duplicate()
    with F.localForm() as f:
        f.set(0.0)
    fpetsc.assemble_vector(F, model.mech.contact.residual_form)
    F.ghostUpdate(addv=PETSc.InsertMode.ADD, mode=PETSc.ScatterMode.REVERSE)
    G = F.duplicate()
    with G.localForm() as g:
        g.array[:] = forces
    G.ghostUpdate(addv=PETSc.InsertMode.ADD, mode=PETSc.ScatterMode.REVERSE)
    return F, G


def eval_point(expr, mesh, point=(1 / 3, 1 / 3)) -> np.ndarray:
    """Value of a UFL expression at a reference point of local cell 0 (constant-data tests)."""
    from dolfinx import fem

    e = fem.Expression(expr, np.array([point]))
    return e.eval(np.array([0], dtype=np.int32)).reshape(expr.ufl_shape)


def unit_mesh(comm, n: int = 2):
    from dolfinx import mesh

    return mesh.create_unit_square(comm, n, n)


def by_node(res: dict, name: str, t: float) -> np.ndarray:
    """P1 values of a read_results() dict ordered by node coordinates (partitions number nodes differently)."""
    x = np.round(res["geometry"], 12)
    return res["fields"][name][t][np.lexsort(x.T[::-1])]


def by_cell(res: dict, name: str, t: float) -> np.ndarray:
    """Cell values ordered by cell midpoints."""
    x = np.round(res["geometry"][res["topology"]].mean(axis=1), 12)
    return res["fields"][name][t][np.lexsort(x.T[::-1])]


def mpi_env() -> dict:
    """The environment for mpirun as root (as the machines here run it)."""
    return dict(os.environ, OMPI_ALLOW_RUN_AS_ROOT="1", OMPI_ALLOW_RUN_AS_ROOT_CONFIRM="1")


def solver_cmd(args: list[str], nproc: int = 1, fault: str | None = None) -> list[str]:
    """``python -m solver ARGS`` (``python -m studies ARGS`` for a study or benchmark), under
    ``mpirun -n NPROC --oversubscribe`` when nproc > 1; ``fault``: with that fault injected into the
    XDMF writer (tests/faults.py)."""
    module = "studies" if args[:1] in (["bench"], ["study"], ["convergence"]) else "solver"
    cmd = [sys.executable, "-m", module, *args] if fault is None else faults.command(fault, ["-m", module, *args])
    return ["mpirun", "-n", str(nproc), "--oversubscribe", *cmd] if nproc > 1 else cmd


def run_cli(args: list[str], nproc: int = 1, timeout: float = 600, fault: str | None = None) -> subprocess.CompletedProcess:
    """Run the command line as a user would (from the repository root), capturing its output."""
    return subprocess.run(solver_cmd(args, nproc, fault), cwd=ROOT, env=mpi_env(), capture_output=True, text=True,
                          timeout=timeout)


def checkpointed(cfg, comm, directory, levels: int):
    """Levels 0 ... levels - 1 of the scene, a checkpoint of the last written to ``directory``, and a model built
    afresh (not read yet): (the model, its stepper, the fresh model)."""
    from solver.io import checkpoint
    from solver.run.model import build_model
    from solver.run.stepper import Stepper

    model = build_model(cfg, comm)
    stepper = Stepper(model)
    for n in range(levels):
        stepper.step(n)
    checkpoint.write(directory, model, levels - 1, (levels - 1) * cfg.time.k, part=0)
    return model, stepper, build_model(cfg, comm)


@contextlib.contextmanager
def read_only(path: Path):
    """``path`` read-only for this process for the block, as a folder another user made is: mode bits for a user,
    a read-only bind mount for root (who writes through mode bits); skips the test where neither can be done."""
    if os.geteuid() != 0:
        mode = path.stat().st_mode
        path.chmod(0o555)
        try:
            yield "Permission denied"
        finally:
            path.chmod(mode)
        return
    bind = subprocess.run(["mount", "--bind", str(path), str(path)], capture_output=True)
    if bind.returncode:
        pytest.skip("cannot bind-mount here to make a read-only folder")
    try:
        if subprocess.run(["mount", "-o", "remount,ro,bind", str(path)], capture_output=True).returncode:
            pytest.skip("cannot remount read-only here")
        yield "Read-only file system"
    finally:
        subprocess.run(["umount", str(path)], capture_output=True)
