"""solver.method = "newton_condensed" (solver/solvers/condensed.py): the contact levels solved on the contact
dofs through K's one factorization reach the same solution as Newton's, level by level, with no factorization
of K + C, and the same on every number of ranks."""

import numpy as np
import pytest
from conftest import ROOT
from mpi4py import MPI
from petsc4py import PETSc

from solver.config import load
from solver.io.results import run
from solver.run.model import build_model
from solver.solvers.condensed import CondensedNewtonSolver

# test_energy_newton.py's scene: hard.toml with P2, where at t = 0.45 plain Newton cycles and needs its fallback
CYCLING = ["discretization.u_degree=2", "time.k=0.05", "time.T=0.45", "output.xdmf=false"]


def _run(comm, method: str, extra=()):
    model = build_model(load(ROOT / "configs" / "hard.toml", [*CYCLING, f"solver.method='{method}'", *extra]), comm)
    return model, run(model, None)


def test_the_same_levels_as_newton_with_one_factorization(comm):
    """Every level solved to Newton's tolerance, the same contact force, strain and damage as Newton + fallback,
    and the only factorization in the run is K's (plain Newton and newton_energy factor K + C at every change
    of the active set)."""
    model, rows = _run(comm, "newton_condensed")
    solver = model.mech.solver
    assert isinstance(solver, CondensedNewtonSolver) and solver.on and solver.fallbacks == 0
    assert sum(r["factorizations"] for r in rows) == 1
    assert solver.reduced_iterations > 0  # the moving levels were iterated on the contact dofs
    ref_model, ref = _run(comm, "newton")
    assert ref_model.mech.solver.fallbacks >= 1
    assert max(r["newton_iterations"] for r in rows) < max(r["newton_iterations"] for r in ref)
    for a, b in zip(rows, ref, strict=True):
        assert a["contact_force"] == pytest.approx(b["contact_force"], rel=1e-8, abs=1e-10)
        assert a["strain_norm"] == pytest.approx(b["strain_norm"], rel=1e-8)
        assert a["zeta_norm"] == pytest.approx(b["zeta_norm"], rel=1e-8)
    if comm.size == 1:
        u, uref = model.u.x.array, ref_model.u.x.array
        assert np.max(np.abs(u - uref)) <= 1e-8 * np.max(np.abs(uref))
    else:
        for kind in (PETSc.NormType.NORM_2, PETSc.NormType.NORM_INFINITY):
            assert model.u.vector.norm(kind) == pytest.approx(ref_model.u.vector.norm(kind), rel=1e-9)
    problem = model.mech.problem  # the last level's residual, evaluated again from scratch
    scale = problem.begin_level(rows[-1]["t"])
    problem.evaluate(model.u.vector, problem.r)
    assert problem.r.norm() <= model.cfg.solver.rtol * scale


def test_the_same_levels_on_one_rank(comm):
    if comm.size == 1:
        pytest.skip("compares a parallel run with a serial one")
    _, rows = _run(comm, "newton_condensed")
    _, srows = _run(MPI.COMM_SELF, "newton_condensed")
    for a, b in zip(rows, srows, strict=True):
        assert a["contact_force"] == pytest.approx(b["contact_force"], rel=1e-8, abs=1e-10)
        assert a["strain_norm"] == pytest.approx(b["strain_norm"], rel=1e-9)


@pytest.mark.parametrize("extra", [["solver.linear='iterative'"], ["memory.rule='trapezoid'", "time.T=0.1"]])
def test_where_it_does_not_apply_it_is_newton_energy(comm, extra):
    """An iterative linear solver (no factorization of K to reuse) or the implicit memory term (no energy):
    newton_energy's levels, step for step."""
    model, rows = _run(comm, "newton_condensed", [*extra, "time.T=0.1"])
    assert not model.mech.solver.on
    _, ref = _run(comm, "newton_energy", [*extra, "time.T=0.1"])
    assert [r["newton_iterations"] for r in rows] == [r["newton_iterations"] for r in ref]
    rel = 1e-12 if comm.size == 1 else 1e-8  # two builds on 2 ranks may partition differently
    assert [r["contact_force"] for r in rows] == pytest.approx([r["contact_force"] for r in ref], rel=rel)
