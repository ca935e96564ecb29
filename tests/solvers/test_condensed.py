"""solver.method = "newton_condensed" (solver/solvers/condensed.py): the contact levels solved on the contact
dofs through K's one factorization reach the same solution as Newton's, level by level, with no factorization
of K + C, and the same on every number of ranks."""

import numpy as np
import pytest
import scipy.linalg as sla
from conftest import ROOT
from mpi4py import MPI
from petsc4py import PETSc

from solver.config import load
from solver.io.results import run
from solver.run.model import build_model
from solver.solvers.condensed import CondensedNewtonSolver
from solver.solvers.energy_newton import EnergyNewtonSolver
from solver.solvers.reduced import Reduced

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
    assert isinstance(solver, CondensedNewtonSolver) and solver.fallbacks == 0
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
    ref_model, ref = _run(comm, "newton_energy", [*extra, "time.T=0.1"])
    # chosen at build time, the registry's instead: newton_energy's method (itself plain Newton without energy)
    assert type(model.mech.solver) is type(ref_model.mech.solver)
    assert isinstance(model.mech.solver, EnergyNewtonSolver) == (extra == ["solver.linear='iterative'"])
    assert [r["newton_iterations"] for r in rows] == [r["newton_iterations"] for r in ref]
    rel = 1e-12 if comm.size == 1 else 1e-8  # two builds on 2 ranks may partition differently
    assert [r["contact_force"] for r in rows] == pytest.approx([r["contact_force"] for r in ref], rel=rel)


def _hard_p2(comm, extra=()):
    """hard.toml with P2 at n = 16, k = 0.01 (the levels where the contact zone moves most: t = 0.25-0.63)."""
    sets = ["discretization.u_degree=2", "discretization.zeta_degree=2", "time.order=2", "output.xdmf=false",
            "solver.method='newton_condensed'", *extra]
    model = build_model(load(ROOT / "configs" / "hard.toml", sets), comm)
    return model, run(model, None)


def test_the_points_are_the_forms(comm):
    """PointContact's j_B and C_BB (sparse products at the quadrature points) equal the facet assembly's (Reduced's
    forms) at displacements on both sides of the contact, on any number of ranks."""
    model, _ = _hard_p2(comm, ["time.T=0.3"])
    solver = model.mech.solver
    assert solver.points is not None
    forms, pc = Reduced(solver.cond, solver.problem, solver.reduced_work, solver.core.settings, 1.0), solver.points
    a, S = solver.cond.u0_B, solver.cond.S
    rng = np.random.default_rng(comm.size)
    v0 = solver.dofs.gather(model.u.vector.array_r[solver.dofs.local])
    for scale in (0.0, 1e-3, 1e-2):
        v = v0 + scale * comm.bcast(rng.standard_normal(len(v0)), root=0) * np.abs(v0).max()
        H, C, _ = forms.evaluate(v)
        r = pc.NB @ v + pc.c
        assert 0 < (r > 0).sum() < len(r)  # points in contact and out of it
        Hp = v - a + S @ pc.force(r)
        # the two compute u_nu at a point with different round-off (~eps |u|), which the law multiplies by 1/mu
        # (1e10): the bound is that error carried through W and S; a wrong N or W would be off by O(|S j_B|)
        roundoff = 10 * np.finfo(float).eps * pc.inv_mu.max() * np.abs(v).max() * np.abs(S).max()
        assert np.abs(H - Hp).max() <= roundoff < 1e-6 * np.abs(S @ pc.force(r)).max()
        Cp = pc.jacobian(pc.state(r))
        assert np.abs(C - Cp).max() <= 1e-12 * np.abs(C).max()


def _dphi(pc, alpha: float, beta: float, r: np.ndarray, s: np.ndarray):
    """phi'(lam) = alpha + lam beta + s.W p(r + lam s), evaluated as line_minimum evaluates it."""
    return lambda lam: alpha + lam * beta + float(s @ (pc.W * pc.pressure(r + lam * s)))


def _dphi_roundoff(pc, alpha: float, beta: float, r: np.ndarray, s: np.ndarray) -> float:
    """A bound on how far a computed phi' at line_minimum's lam may sit from 0, for any summation order.

    Error model (u = eps/2, gamma_n = n u / (1 - n u), Higham's bound for a sum of n products in any order):
    - one evaluation of phi' at lam in [0, 1] is off by at most E = gamma_{n+5} S + u A, where
      S = |alpha| + beta + sum |s| W p(r + max(s, 0)) bounds every term (p is nondecreasing) and the n + 5
      roundings are the n-term dot product, the two additions and the three products in s W p;
      A = sum |s| W p'(r + max(s, 0)) (|r| + |s|) carries the rounding of r + lam s through the law's
      slope, and also covers the kinks -r/s computed to u relative;
    - line_minimum's lam is the root of the chord through two computed values on a segment where phi' is
      linear, so the true phi'(lam) is within E + 6 u S of 0 (the chord is off by at most E, the interpolation
      formula's three roundings move lam by 3 u of a step whose rise is at most 2 S);
    - phi' is nondecreasing, so phi'(lam (1 - 1e-9)) <= phi'(lam) and a second evaluation adds E:
      computed phi'(lam (1 -+ 1e-9)) is <= 2 E + 6 u S, resp. >= -(2 E + 6 u S)."""
    u = np.finfo(float).eps / 2
    n = len(s) + 5
    top = r + np.maximum(s, 0.0)
    S = abs(alpha) + beta + float(np.abs(s) @ (pc.W * pc.pressure(top)))
    A = float(np.abs(s) @ (pc.slopes(pc.state(top)) * (np.abs(r) + np.abs(s))))
    E = n * u / (1 - n * u) * S + u * A
    return 2 * E + 6 * u * S


def test_the_line_search_is_exact_and_looks_ahead(comm):
    """line_minimum's lam is where phi' = (x + lam d - P u0).S^{-1} d + j_B(x + lam d).d changes sign (phi' is
    continuous and nondecreasing), and the set it returns is the one just past lam along d. x is the level's
    solution moved back along d by a random fraction, so that the minimum lies inside (0, 1) across kinks."""
    model, _ = _hard_p2(comm, ["time.T=0.3"])
    solver = model.mech.solver
    pc, a, chol = solver.points, solver.cond.u0_B, solver.cond.chol
    rng = np.random.default_rng(7)
    v = solver.dofs.gather(model.u.vector.array_r[solver.dofs.local])
    stops = crossed = 0
    for _ in range(20):
        d = comm.bcast(rng.standard_normal(len(v)), root=0) * 1e-2 * np.abs(v).max()
        x = v - comm.bcast(rng.uniform(0.1, 0.9), root=0) * d
        w = sla.cho_solve(chol, d)
        alpha, beta, r, s = float((x - a) @ w), float(d @ w), pc.NB @ x + pc.c, pc.NB @ d
        if alpha + float(s @ (pc.W * pc.pressure(r))) >= 0.0:
            d, alpha, s = -d, -alpha, -s  # a descent direction (the sign of phi'(0) can be round-off)
        dphi = _dphi(pc, alpha, beta, r, s)  # bound after the flip: the function line_minimum is given
        lam, state = pc.line_minimum(alpha, beta, r, s)
        bound = _dphi_roundoff(pc, alpha, beta, r, s)
        if lam < 1.0:
            assert dphi(lam * (1 - 1e-9)) <= bound and dphi(lam * (1 + 1e-9)) >= -bound
            stops += 1
            crossed += bool(np.any(pc.kinks(r, s) < lam))
        else:
            assert dphi(1.0) <= bound
        kinks = pc.kinks(r, s)
        after = min([k for k in kinks if k > lam * (1 + 1e-9)] + [1.0])
        assert np.array_equal(state, pc.state(r + 0.5 * (lam + after) * s))
    assert stops > 0 and crossed > 0


def test_moving_levels_in_few_iterations(comm):
    """hard.toml with P2, n = 16: no level above 10 iterations (14 at t = 0.34 before the exact line search,
    the set looking ahead and the predicted set: the line search stopped at the same kink again and again) and
    the whole run in fewer iterations than newton_energy's, with the same levels."""
    _, rows = _hard_p2(comm)
    its = [r["newton_iterations"] for r in rows]
    assert max(its) <= 10
    _, ref = _hard_p2(comm, ["solver.method='newton_energy'"])
    assert sum(its) < sum(r["newton_iterations"] for r in ref)
    for a, b in zip(rows, ref, strict=True):
        assert a["contact_force"] == pytest.approx(b["contact_force"], rel=1e-7, abs=1e-9)
        assert a["strain_norm"] == pytest.approx(b["strain_norm"], rel=1e-9)
        assert a["zeta_norm"] == pytest.approx(b["zeta_norm"], rel=1e-9)


def test_its_options_go_with_it(comm):
    """K's factorization options are the solver's own and leave PETSc's database with it: a process building
    many models (a study, a sweep from Python) filled the database (PETSc error 55) when they stayed."""
    import gc

    def condensed() -> set[str]:
        return {name for name in PETSc.Options().getAll() if name.startswith("mech_condensed_")}

    before = condensed()
    model, _ = _run(comm, "newton_condensed", ["time.T=0.05"])
    assert model.mech.solver.cond is not None and condensed() - before  # it had options while it lived
    del model, _
    gc.collect()
    assert condensed() == before
