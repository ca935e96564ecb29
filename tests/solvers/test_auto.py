"""solver.method = "auto" (solver/solvers/auto.py, the default): Newton's levels while Newton solves them, then
newton_condensed's from the first level it does not; the same solution as Newton + fallback."""

import numpy as np
import pytest
from conftest import ROOT, checkpointed
from petsc4py import PETSc

import solver.solvers.newton as newton_module
from solver.config import load
from solver.io import checkpoint
from solver.io.results import run
from solver.run.model import build_model
from solver.run.stepper import Stepper
from solver.solvers.auto import GROWTH_STEPS, NEWTON_ITERATIONS, AutoSolver
from solver.solvers.cycle_watch import ActiveSetCycleWatch
from solver.solvers.newton import NewtonTest

# test_energy_newton.py's scene: hard.toml with P2, where at t = 0.45 plain Newton cycles and needs its fallback
CYCLING = ["discretization.u_degree=2", "time.k=0.05", "time.T=0.45", "output.xdmf=false"]


def _same_levels(rows, ref, comm) -> None:
    """The same iterations and factorizations; the same results, to the bit on one rank (on 2, two builds may
    partition differently: to round-off)."""
    counts = ("newton_iterations", "factorizations")
    assert [[r[k] for k in counts] for r in rows] == [[r[k] for k in counts] for r in ref]
    for key in ("contact_force", "strain_norm", "zeta_norm"):
        a, b = [r[key] for r in rows], [r[key] for r in ref]
        assert a == b if comm.size == 1 else a == pytest.approx(b, rel=1e-10, abs=1e-12), key


def _run(comm, method: str, extra=(), scene="hard.toml"):
    model = build_model(load(ROOT / "configs" / scene, [*extra, f"solver.method='{method}'"]), comm)
    return model, run(model, None)


def test_it_is_the_default():
    assert load(ROOT / "configs" / "hard.toml").solver.method == "auto"


def test_where_newton_solves_every_level_it_is_newton(comm):
    """Example 1: no level fails, so every level is Newton's, to the bit (iterations and results)."""
    extra = ["mesh.nx=8", "mesh.ny=8", "time.k=0.1", "output.xdmf=false"]
    model, rows = _run(comm, "auto", extra, "example1.toml")
    assert isinstance(model.mech.solver, AutoSolver) and not model.mech.solver.switched
    _, ref = _run(comm, "newton", extra, "example1.toml")
    _same_levels(rows, ref, comm)


def test_from_the_level_newton_fails_it_is_newton_condensed(comm):
    """The cycling scene: the levels are Newton's, to the bit, up to the first one Newton does not solve in
    NEWTON_ITERATIONS (t = 0.3, where Newton takes 10; at t = 0.45 it cycles and needs the fallback) or where its
    residual grows GROWTH_STEPS iterations in a row (t = 0.25 here); that level
    and the later ones are newton_condensed's, with no damped fallback, the same solution as Newton + fallback
    with fewer factorizations, and K factored, not the K + C Newton leaves in K's storage."""
    model, rows = _run(comm, "auto", CYCLING)
    solver = model.mech.solver
    assert solver.switched and solver.fallbacks == 0 and solver.takeover.reduced_iterations > 0
    ref_model, ref = _run(comm, "newton", CYCLING)
    assert ref_model.mech.solver.fallbacks >= 1
    at = solver.switched_at  # the first level Newton does not solve in NEWTON_ITERATIONS (t = 0.3, 10 here), or
    # an earlier one where its residual grew GROWTH_STEPS iterations in a row (t = 0.25)
    assert 0 < at <= next(i for i, r in enumerate(ref) if r["newton_iterations"] > NEWTON_ITERATIONS)
    _same_levels(rows[:at], ref[:at], comm)
    assert sum(r["factorizations"] for r in rows) < sum(r["factorizations"] for r in ref)
    for a, b in zip(rows, ref, strict=True):
        assert a["contact_force"] == pytest.approx(b["contact_force"], rel=1e-8, abs=1e-10)
        assert a["strain_norm"] == pytest.approx(b["strain_norm"], rel=1e-8)
        assert a["zeta_norm"] == pytest.approx(b["zeta_norm"], rel=1e-8)
    # the Schur complement on the contact dofs is K's, as newton_condensed's own (Newton leaves K + C in K's
    # storage; factored as it was, the condensed levels took 676 iterations on hard.toml P2 n = 16, 160 alone)
    cond_model, _ = _run(comm, "newton_condensed", CYCLING)
    S, S_ref = solver.takeover.cond.S, cond_model.mech.solver.cond.S
    if comm.size == 1:
        assert np.array_equal(S, S_ref)
    else:  # the contact dofs in the order of each build's partition
        assert np.sort(np.diag(S)) == pytest.approx(np.sort(np.diag(S_ref)), rel=1e-10)
        assert np.linalg.norm(S) == pytest.approx(np.linalg.norm(S_ref), rel=1e-10)
    problem = model.mech.problem  # the last level's residual, evaluated again from scratch
    scale = problem.begin_level(rows[-1]["t"])
    problem.evaluate(model.u.vector, problem.r)
    assert problem.r.norm() <= model.cfg.solver.rtol * scale


def test_a_first_contact_goes_to_the_takeovers_own_path(comm):
    """configs/moving_contact.toml at P2 (n = 16): level 1 is the first contact (level 0 has no load), which
    Newton's FIRST_STEPS iterations do not solve. newton_condensed has a compliance path of its own (on the contact
    dofs), so auto hands the level over there, without Newton's path in the full space (its stages' factorizations
    were lost with the level): the same solution as newton_condensed's, in fewer iterations and factorizations than
    Newton's path took (26 and 18 before, 12 and 4 now). At the run's first level Newton keeps its path."""
    from solver.solvers.continuation import FIRST_STEPS

    extra = ["discretization.u_degree=2", "time.T=0.02", "output.xdmf=false"]
    model, rows = _run(comm, "auto", extra, "moving_contact.toml")
    solver = model.mech.solver
    assert solver.takeover.has_path and solver.switched_at == 1 and solver.newton.continuation.levels == 0
    cond_model, ref = _run(comm, "newton_condensed", extra, "moving_contact.toml")
    condensed_level = ref[1]["newton_iterations"]
    # Newton's FIRST_STEPS, then the take-over's level from its start; Newton factors K + C once a step, the
    # take-over K once
    assert rows[1]["newton_iterations"] == FIRST_STEPS + condensed_level
    assert rows[1]["factorizations"] == FIRST_STEPS + 1
    for a, b in zip(rows, ref, strict=True):
        assert a["contact_force"] == pytest.approx(b["contact_force"], rel=1e-9, abs=1e-12)
        assert a["strain_norm"] == pytest.approx(b["strain_norm"], rel=1e-9)


def test_a_first_contact_at_the_runs_first_level_keeps_newtons_path(comm):
    """Hertz line contact (tests/solvers/test_continuation.py), a one-level run: its first contact is level 0, where
    Newton keeps its path (the hand-over would pay S's build for it: 1.09 and 1.27 times the time on the Hertz
    scenes at P1 n = 200 and P2 n = 100) and settles the level without the take-over."""
    from test_continuation import hertz_line

    from solver.config import from_dict

    model = build_model(from_dict(hertz_line(40)), comm)
    row = Stepper(model).step(0)
    solver = model.mech.solver
    assert solver.takeover.has_path and solver.newton.take_path and not solver.switched
    assert solver.newton.continuation.levels == 1 and row["factorizations"] == row["newton_iterations"]


def test_without_a_fallback_a_failed_level_fails(comm):
    """solver.newton_fallback = false: nothing takes a failed level over, as with Newton."""
    from solver.errors import DisplacementSolveError

    with pytest.raises(DisplacementSolveError):
        _run(comm, "auto", [*CYCLING, "solver.newton_fallback=false"])


def test_a_restart_goes_on_with_the_method_it_had(comm, shared_tmp):
    """The switch is carried by checkpoints: a run restarted after it solves the next levels as newton_condensed,
    with the same iterations and the same u (to the bit on one rank)."""
    cfg = load(ROOT / "configs" / "hard.toml", [*CYCLING, "time.T=0.6", "solver.method='auto'"])
    model, stepper, fresh = checkpointed(cfg, comm, shared_tmp, 11)
    assert model.mech.solver.switched
    checkpoint.read(shared_tmp, fresh)
    assert fresh.mech.solver.switched_at == model.mech.solver.switched_at
    again = Stepper(fresh)
    for n in range(11, 13):
        a, b = stepper.step(n), again.step(n)
        assert a["newton_iterations"] == b["newton_iterations"] and a["factorizations"] == b["factorizations"] - (
            1 if n == 11 else 0), n  # the restarted process factors K once more, at its first level
        if comm.size == 1:
            assert np.array_equal(fresh.u.x.array, model.u.x.array), n
        else:  # two builds may partition differently: the norms of u
            for kind in (PETSc.NormType.NORM_2, PETSc.NormType.NORM_INFINITY):
                assert fresh.u.vector.norm(kind) == pytest.approx(model.u.vector.norm(kind), rel=1e-10), n


def test_a_residual_growing_in_a_row_stops_newton_only_where_asked(comm):
    """NewtonTest's growth test (auto's Newton, which has a take-over): GROWTH_STEPS iterations in a row each raising
    ||F|| stop the solve; a fall in between, or no limit set, goes on."""
    test = NewtonTest(1e-12, 25, ActiveSetCycleWatch(comm, False), None)
    R = PETSc.SNES.ConvergedReason
    norms = [1.0, 0.5, 0.6, 0.4, 0.7, 0.9]
    assert [test(it, 1.0, 1.0, f) for it, f in enumerate(norms)] == [R.ITERATING] * len(norms)
    test.growth_limit = GROWTH_STEPS
    reasons = [test(it, 1.0, 1.0, f) for it, f in enumerate(norms)]
    assert reasons == [R.ITERATING] * (len(norms) - 1) + [R.DIVERGED_DTOL]


def test_the_level_handed_over_gets_the_fallback_budget():
    """The level Newton fails is solved by the take-over with FALLBACK_IT_FACTOR times its limit (the damped
    fallback's budget: a first contact in 3-D takes some 40 iterations), the later levels too (the sphere pressed
    further takes as many), and the take-over starts where it may from the compliance path's end, else from the level's start."""
    from types import SimpleNamespace

    from solver.errors import DisplacementSolveError
    from solver.physics.displacement import SolveInfo
    from solver.solvers.damped_newton import FALLBACK_IT_FACTOR

    class Vec:
        def __init__(self, tag):
            self.tag = tag

        def duplicate(self):
            return Vec("")

        def copy(self, other):
            other.tag = self.tag

    u = SimpleNamespace(vector=Vec("level start"), x=SimpleNamespace(scatter_forward=lambda: None))
    core = SimpleNamespace(factorizations=0, test=SimpleNamespace(growth_limit=None), iterative=False,
                           begin_level=lambda: None)
    core.use_direct = lambda: setattr(core, "iterative", False)
    core.solve_level = lambda solve, start: newton_module.NewtonCore.solve_level(core, solve, start)  # the real one on this core

    class FailingNewton:
        problem, fallbacks, path_end = SimpleNamespace(u=u), 0, None

        def __init__(self):
            self.core = core

        def solve(self, scale):
            u.vector.tag = "newton's end"
            raise DisplacementSolveError("SNES", "DIVERGED_MAX_IT", 8, [1.0], 1e-10)

    class Takeover:
        fallbacks, starts_anywhere, has_path = 0, False, False

        def __init__(self):
            self.test = SimpleNamespace(max_it=25)
            self.seen = []

        def solve(self, scale):
            self.seen.append((self.test.max_it, u.vector.tag))
            return SolveInfo(3, 1, 0.0, "CONVERGED")

    newton, takeover = FailingNewton(), Takeover()
    auto = AutoSolver(newton, takeover)
    info = auto.solve(1.0)
    assert info.iterations == 3 + 8 and auto.switched
    auto.solve(1.0)
    assert takeover.seen == [(FALLBACK_IT_FACTOR * 25, "level start")] * 2 and takeover.test.max_it == 25
    # a take-over that may start anywhere starts a first contact where the compliance path ended
    u.vector.tag = "level start"
    newton2, takeover2 = FailingNewton(), Takeover()
    takeover2.starts_anywhere = True
    newton2.path_end = Vec("path's end")
    AutoSolver(newton2, takeover2).solve(1.0)
    assert takeover2.seen == [(FALLBACK_IT_FACTOR * 25, "path's end")]
    # ... and where it fails from there, from the level's start
    u.vector.tag = "level start"
    newton3, takeover3 = FailingNewton(), Takeover()
    takeover3.starts_anywhere = True
    newton3.path_end = Vec("path's end")
    calls = []

    def fails_first(scale):
        calls.append(u.vector.tag)
        if len(calls) == 1:
            raise DisplacementSolveError("SNES", "DIVERGED_LINEAR_SOLVE", 4, [1.0], 1e-10, linear_reason=-8)
        return SolveInfo(5, 1, 0.0, "CONVERGED")

    takeover3.solve = fails_first
    info = AutoSolver(newton3, takeover3).solve(1.0)
    assert calls == ["path's end", "level start"] and info.iterations == 8 + 4 + 5
    # ... unless the failed linear solve was the iterative solver's: then from the path's end again, solved directly
    u.vector.tag = "level start"
    newton4, takeover4 = FailingNewton(), Takeover()
    takeover4.starts_anywhere = True
    newton4.path_end = Vec("path's end")
    calls.clear()
    takeover4.solve = fails_first
    core.iterative = True
    info = AutoSolver(newton4, takeover4).solve(1.0)
    assert calls == ["path's end", "path's end"] and not core.iterative and info.iterations == 8 + 4 + 5


RETRY = ["mesh.nx=8", "mesh.ny=8", "time.k=0.1", "time.T=0.3", "output.xdmf=false"]
FAILING_KRYLOV = ["solver.linear='iterative'", "solver.petsc_options.mech_ksp_max_it=1"]


@pytest.mark.parametrize("direct_levels", [None, 1])
def test_a_failed_iterative_linear_solve_is_solved_again_directly(comm, direct_levels, monkeypatch):
    """CG + AMG stopped after one iteration (mech_ksp_max_it = 1) fails Newton's first linear solve: auto puts the
    core on the direct solver and hands the level over, which it then solves; the levels match a direct run's to
    round-off (the direct run's Newton solves them all). With DIRECT_LEVELS = 1 each later level goes back to CG +
    AMG, fails again and is solved directly again (one switch a level); with None the core stays direct."""
    monkeypatch.setattr(newton_module, "DIRECT_LEVELS", direct_levels)
    model, rows = _run(comm, "auto", [*RETRY, *FAILING_KRYLOV], "example1.toml")
    solver = model.mech.solver
    assert solver.switched_at == 0 and not solver.core.iterative
    assert solver.core.direct_switches == (1 if direct_levels is None else len(rows))
    ref_model, ref = _run(comm, "auto", [*RETRY, "solver.linear='mumps'"], "example1.toml")
    assert not ref_model.mech.solver.switched
    for key in ("contact_force", "strain_norm"):
        assert [r[key] for r in rows] == pytest.approx([r[key] for r in ref], rel=1e-10), key
    assert model.u.vector.norm() == pytest.approx(ref_model.u.vector.norm(), rel=1e-10)
    # a checkpoint carries the switch: a model restored from these scalars solves directly from the start, and goes
    # back to the iterative solver at the level where the checkpointed run would
    fresh = build_model(load(ROOT / "configs" / "example1.toml",
                             [*RETRY, "solver.linear='iterative'", "solver.method='auto'"]), comm)
    assert fresh.mech.solver.core.iterative
    fresh.mech.restore_scalars(model.mech.scalars())
    assert not fresh.mech.solver.core.iterative and fresh.mech.solver.core.ksp.getType() == "preonly"
    fresh.mech.solver.core.begin_level()
    assert fresh.mech.solver.core.iterative == (direct_levels is not None)


def test_a_restart_after_the_switch_takes_the_same_levels(comm, shared_tmp, monkeypatch):
    """A run restarted from a checkpoint written on the direct solver (after level 1: DIRECT_LEVELS = 1 sends it
    back to CG + AMG at level 2) takes the same iterations, factorizations and solution as the run it continues."""
    monkeypatch.setattr(newton_module, "DIRECT_LEVELS", 1)
    cfg = load(ROOT / "configs" / "example1.toml", [*RETRY, *FAILING_KRYLOV, "solver.method='auto'"])
    model, stepper, fresh = checkpointed(cfg, comm, shared_tmp, 2)
    assert not model.mech.solver.core.iterative and model.mech.solver.core.direct_levels == 1
    checkpoint.read(shared_tmp, fresh)
    again = Stepper(fresh)
    for n in range(2, 4):
        a, b = stepper.step(n), again.step(n)
        assert a["newton_iterations"] == b["newton_iterations"] and a["factorizations"] == b["factorizations"] - (
            1 if n == 2 else 0), n  # the restarted process sets its solver up once more, at its first level
        assert a["contact_force"] == pytest.approx(b["contact_force"], rel=1e-12), n
        assert fresh.u.vector.norm() == pytest.approx(model.u.vector.norm(), rel=1e-12), n
        assert fresh.mech.solver.core.iterative == model.mech.solver.core.iterative, n


@pytest.mark.parametrize("direct_levels", [1, 2])
def test_after_the_levels_on_the_direct_solver_it_is_iterative_again(comm, direct_levels, monkeypatch):
    """Where CG + AMG can solve the levels, a core put on the direct solver (as a failed Krylov solve puts it) solves
    DIRECT_LEVELS levels there and the next ones iteratively, to the same solution as a run that stayed
    iterative."""
    monkeypatch.setattr(newton_module, "DIRECT_LEVELS", direct_levels)
    model = build_model(load(ROOT / "configs" / "example1.toml", [*RETRY, "solver.linear='iterative'"]), comm)
    core = model.mech.solver.core
    core.use_direct()
    stepper = Stepper(model)
    rows = [stepper.step(n) for n in range(4)]
    assert core.iterative and core.direct_switches == 1
    assert all(r["krylov_iterations"] == 0 for r in rows[:direct_levels])
    assert all(r["krylov_iterations"] > 0 for r in rows[direct_levels:])
    _, ref = _run(comm, "auto", [*RETRY, "solver.linear='iterative'"], "example1.toml")
    for key in ("contact_force", "strain_norm"):
        assert [r[key] for r in rows] == pytest.approx([r[key] for r in ref], rel=1e-10), key


@pytest.mark.parametrize("method", ["newton", "newton_energy"])
def test_newton_too_solves_a_level_again_directly(comm, method, caplog):
    """newton and newton_energy, where CG + AMG fails (mech_ksp_max_it = 1), solve the level again on the direct
    solver, saying so in one line of the log, to a MUMPS run's results (to 1e-10)."""
    import logging

    with caplog.at_level(logging.INFO, logger="solver"):
        model, rows = _run(comm, method, [*RETRY, *FAILING_KRYLOV], "example1.toml")
    assert model.mech.solver.core.direct_switches >= 1
    lines = [r for r in caplog.records if "iterative linear solver failed" in r.getMessage()]
    assert len(lines) == model.mech.solver.core.direct_switches and "MUMPS" in lines[0].getMessage()
    _, ref = _run(comm, method, [*RETRY, "solver.linear='mumps'"], "example1.toml")
    for key in ("contact_force", "strain_norm"):
        assert [r[key] for r in rows] == pytest.approx([r[key] for r in ref], rel=1e-10), key


def test_where_the_iterative_solves_succeed_it_stays_iterative(comm):
    """The same scene with CG + AMG's own limits: no linear solve fails, no switch to the direct solver."""
    model, _ = _run(comm, "auto", [*RETRY, "solver.linear='iterative'"], "example1.toml")
    assert model.mech.solver.core.direct_switches == 0 and model.mech.solver.core.iterative
