"""solver.method = "newton_energy" (solver/solvers/energy_newton.py): Newton globalized on the level's energy
from the first iteration solves the levels where plain Newton cycles, without a fallback, to the same
solution, and the same on every number of ranks."""

import numpy as np
import pytest
from conftest import ROOT
from mpi4py import MPI
from petsc4py import PETSc

from solver.config import load
from solver.errors import ConfigError
from solver.io.results import run
from solver.run.model import build_model
from solver.solvers.energy_newton import EnergyNewtonSolver

# tests/solvers/test_damped_newton.py's scene: hard.toml with P2, where at t = 0.45 plain Newton cycles
CYCLING = ["discretization.u_degree=2", "time.k=0.05", "time.T=0.45", "output.xdmf=false"]


def _run(comm, method: str, extra=()):
    model = build_model(load(ROOT / "configs" / "hard.toml", [*CYCLING, f"solver.method='{method}'", *extra]), comm)
    return model, run(model, None)


def test_the_method_is_a_choice_of_the_scene():
    cfg = load(ROOT / "configs" / "hard.toml", ["solver.method='newton_energy'", "solver.linear='iterative'"])
    assert cfg.solver.method == "newton_energy"
    with pytest.raises(ConfigError, match="solver.method"):
        load(ROOT / "configs" / "hard.toml", ["solver.method='newton_energie'"])


def test_it_solves_the_cycling_levels_without_fallback_in_fewer_iterations(comm):
    """Plain Newton cycles at t = 0.45 and its fallback restarts the level; newton_energy needs neither, and
    the whole run takes fewer iterations and factorizations than Newton + fallback."""
    model, rows = _run(comm, "newton_energy")
    solver = model.mech.solver
    assert isinstance(solver, EnergyNewtonSolver) and solver.fallbacks == 0
    ref_model, ref = _run(comm, "newton")
    assert ref_model.mech.solver.fallbacks >= 1  # the scene is one where today's Newton needs the fallback
    its = [r["newton_iterations"] for r in rows]
    assert sum(its) < sum(r["newton_iterations"] for r in ref)
    assert max(its) < max(r["newton_iterations"] for r in ref)
    assert sum(r["factorizations"] for r in rows) < sum(r["factorizations"] for r in ref)
    # the same discrete solution, to the solver tolerance, at every level
    for a, b in zip(rows, ref):
        assert a["contact_force"] == pytest.approx(b["contact_force"], rel=1e-8, abs=1e-10)
        assert a["strain_norm"] == pytest.approx(b["strain_norm"], rel=1e-8)
        assert a["zeta_norm"] == pytest.approx(b["zeta_norm"], rel=1e-8)
    if comm.size == 1:  # the same dof numbering: u itself
        u, uref = model.u.x.array, ref_model.u.x.array
        assert np.max(np.abs(u - uref)) <= 1e-8 * np.max(np.abs(uref))
    else:  # two builds may partition differently: the norms of u
        norm = PETSc.NormType
        for kind in (norm.NORM_2, norm.NORM_INFINITY):
            assert model.u.vector.norm(kind) == pytest.approx(ref_model.u.vector.norm(kind), rel=1e-9)
    # and the last level's residual, evaluated again, meets the tolerance
    problem = model.mech.problem
    scale = problem.begin_level(rows[-1]["t"])
    problem.evaluate(model.u.vector, problem.r)
    assert problem.r.norm() <= model.cfg.solver.rtol * scale


def test_the_same_levels_on_one_rank(comm):
    if comm.size == 1:
        pytest.skip("compares a parallel run with a serial one")
    _, rows = _run(comm, "newton_energy")
    _, srows = _run(MPI.COMM_SELF, "newton_energy")
    for a, b in zip(rows, srows):
        assert a["contact_force"] == pytest.approx(b["contact_force"], rel=1e-8, abs=1e-10)
        assert a["strain_norm"] == pytest.approx(b["strain_norm"], rel=1e-9)


def test_without_energy_it_is_plain_newton(comm):
    """The trapezoidal memory rule's implicit term has no energy: the level is plain Newton's, step for step."""
    extra = ["memory.rule='trapezoid'", "time.T=0.1"]
    _, rows = _run(comm, "newton_energy", extra)
    _, ref = _run(comm, "newton", extra)
    assert [r["newton_iterations"] for r in rows] == [r["newton_iterations"] for r in ref]
    assert [r["contact_force"] for r in rows] == pytest.approx([r["contact_force"] for r in ref], rel=1e-12)
