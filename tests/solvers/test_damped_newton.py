"""The damped fallback of the semismooth Newton (solver/solvers/damped_newton.py): a level on which plain Newton cycles
between active sets is solved by it, the same on every number of ranks."""

import pytest
from conftest import ROOT
from mpi4py import MPI

from solver.config import load
from solver.errors import DisplacementSolveError
from solver.io.results import run
from solver.run.model import build_model

# configs/hard.toml (a large swinging traction, mu = 1e-10) with P2 on its 16 x 16 mesh: at t = 0.45 plain
# Newton cycles through three active sets until max_it
CYCLING = ["discretization.u_degree=2", "time.k=0.05", "time.T=0.45", "output.xdmf=false", "solver.method='newton'"]


def _run(comm, extra=()):
    model = build_model(load(ROOT / "configs" / "hard.toml", [*CYCLING, *extra]), comm)
    return model, run(model, None)


def test_plain_newton_cycles_on_the_scene(comm):
    """Without the fallback (solver.newton_fallback = false) the scene fails (so the next test is about a real
    failure)."""
    with pytest.raises(DisplacementSolveError) as err:
        _run(comm, ["solver.newton_fallback=false"])
    # the linear law makes each iterate a function of the last active set: a set met again is a cycle, and the
    # level stops there instead of at max_it
    assert err.value.reason == "DIVERGED_ACTIVE_SET_CYCLE"
    assert err.value.step == 9
    assert err.value.iterations < load(ROOT / "configs" / "hard.toml").solver.max_it


def test_without_cycle_detection_the_level_runs_to_max_it(comm, monkeypatch):
    """The cycle is real: plain Newton left to run does not converge on that level."""
    from solver.solvers import newton

    original = newton.NewtonCore.__init__

    def blind(self, *a, **k):
        original(self, *a, **k)
        self.cycles.enabled = False

    monkeypatch.setattr(newton.NewtonCore, "__init__", blind)
    with pytest.raises(DisplacementSolveError) as err:
        _run(comm, ["solver.newton_fallback=false"])
    assert err.value.reason == "DIVERGED_MAX_IT" and err.value.step == 9


def test_the_damped_fallback_solves_the_cycling_level(comm):
    model, rows = _run(comm)
    newton = model.mech.solver
    assert newton.fallbacks >= 1
    assert len(rows) == 10
    # the converged level's residual, evaluated again: within the tolerance it was solved to
    problem = model.mech.problem
    scale = problem.begin_level(rows[-1]["t"])
    problem.evaluate(model.u.vector, problem.r)
    assert problem.r.norm() <= model.cfg.solver.rtol * scale
    # and the same levels on one rank (the partition does not change the answer)
    if comm.size > 1:
        serial, srows = _run(MPI.COMM_SELF)
        for a, b in zip(rows, srows):
            assert a["strain_norm"] == pytest.approx(b["strain_norm"], rel=1e-9)
            assert a["contact_force"] == pytest.approx(b["contact_force"], rel=1e-8, abs=1e-10)


def test_a_damped_step_too_short_to_move_x_is_not_taken_for_convergence(comm):
    """hard.toml with P2 u and zeta, k = 0.0125: at t = 0.3375 the fallback's line search stops a step at a kink
    of the energy near its start (lam ~ 1e-6), so x moves by less than rtol |x| while F is far from zero. The
    step-size test judged that damped step and accepted the level with a residual of 4.3 (its contact force off
    the trend by 2 %); judging the Newton step, the iteration goes on, and every level meets the tolerance."""
    model, rows = _run(comm, ["discretization.zeta_degree=2", "time.order=2", "time.k=0.0125", "time.T=0.3375"])
    assert model.mech.solver.fallbacks >= 1
    problem = model.mech.problem
    assert max(r["residual"] for r in rows) <= model.cfg.solver.rtol * problem.begin_level(rows[-1]["t"])
