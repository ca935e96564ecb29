"""The step controller of adaptive runs (solver/run/adaptive.py)."""

from __future__ import annotations

import numpy as np
import pytest
import ufl
from conftest import ROOT
from dolfinx import fem
from mpi4py import MPI

from solver.config import load
from solver.run.adaptive import SHARE, Snapshot, StepController, load_kinks, lumped_mass
from solver.run.model import build_model
from solver.run.stepper import Stepper, levels


def _scene(*sets):
    return load(ROOT / "configs/hard.toml", ["mesh.nx=6", "mesh.ny=6", "time.T=0.6", "time.k=0.01",
                                             "time.adaptive=true", *sets])


def test_steps_land_on_table_kinks_output_times_and_T_and_meet_the_tolerance(comm):
    cfg = _scene("time.tolerance=1e-2", "output.times=[0.25]")
    assert load_kinks(cfg) == [0.5]
    rows = list(levels(build_model(cfg, comm)))
    t = [r["t"] for r in rows]
    assert 0.25 in t and 0.5 in t and t[-1] == 0.6 and all(b > a for a, b in zip(t, t[1:]))
    assert np.allclose(np.cumsum([r["k"] for r in rows]), t, rtol=0, atol=1e-12)
    # the steps' errors (the growth of the accumulated error's norm) add up within the tolerance's share
    assert sum(max(r["error_estimate"], 0.0) for r in rows) <= SHARE * 1e-2


def test_the_time_error_is_within_the_tolerance_against_a_fine_uniform_run(comm):
    """Reliability: the adaptive run's time error at T (same mesh) in the paper's norm is below time.tolerance,
    and the first steps (damage falling fast) are smaller than the last ones (damage held at zeta*)."""
    tol = 1e-2
    adaptive = build_model(_scene(f"time.tolerance={tol}"), comm)
    rows = list(levels(adaptive))
    fine = build_model(_scene("time.adaptive=false", "time.k=0.0005"), comm)
    list(levels(fine))
    du = fem.Function(fine.u.function_space)
    du.x.array[:] = adaptive.u.x.array - fine.u.x.array
    e = ufl.sym(ufl.grad(du))
    err = np.sqrt(comm.allreduce(fem.assemble_scalar(fem.form(ufl.inner(e, e) * ufl.dx)), op=MPI.SUM))
    dz = fem.Function(fine.damage.V)
    dz.x.array[:] = adaptive.damage.zeta.x.array - fine.damage.zeta.x.array
    err += np.sqrt(comm.allreduce(fem.assemble_scalar(fem.form(dz * dz * ufl.dx)), op=MPI.SUM))
    assert err <= tol
    ks = [r["k"] for r in rows[1:]]
    assert np.median(ks[:5]) < np.median(ks[-5:])


@pytest.mark.parametrize("degree", [1, 2])
def test_the_damage_estimate_works_for_p2_zeta(comm, degree):
    """The nodes' lumped masses are positive and add up to the domain's area for P1 and P2 zeta (P2's row sums vanish
    at the vertices: the estimate was NaN, every trial accepted), so a P2-zeta run is controlled: its steps follow
    the estimate and its time error is within the tolerance against a fine uniform run."""
    tol = 1e-2
    sets = [f"discretization.zeta_degree={degree}", f"discretization.u_degree={degree}"]
    adaptive = build_model(_scene(f"time.tolerance={tol}", *sets), comm)
    m = lumped_mass(adaptive.damage.V)
    assert m.min() > 0 and np.isclose(comm.allreduce(float(m.sum()), op=MPI.SUM), 1.0, rtol=1e-12)
    rows = list(levels(adaptive))
    est = [r["error_estimate"] for r in rows[2:]]
    assert all(np.isfinite(est)) and max(est) > 0
    assert len({round(r["k"], 12) for r in rows[1:]}) > 2  # the steps change with the estimate
    fine = build_model(_scene("time.adaptive=false", "time.k=0.0005", *sets), comm)
    list(levels(fine))
    dz = fem.Function(fine.damage.V)
    dz.x.array[:] = adaptive.damage.zeta.x.array - fine.damage.zeta.x.array
    assert np.sqrt(comm.allreduce(fem.assemble_scalar(fem.form(dz * dz * ufl.dx)), op=MPI.SUM)) <= tol


def test_a_rejected_trial_is_undone_exactly(comm):
    """Snapshot, a trial step, restore, the same step again: the same numbers as the step taken once."""
    cfg = _scene("time.order=2")
    a, b = build_model(cfg, comm), build_model(cfg, comm)
    sa, sb = Stepper(a), Stepper(b)
    for s in (sa, sb):
        s.step(0, 0.0, 0.0, None)
        s.step(1, 0.01, 0.01, None)
    snap = Snapshot(b)
    sb.step(2, 0.05, 0.04, 0.01)  # a trial that is thrown away
    snap.restore()
    ra, rb = sa.step(2, 0.03, 0.02, 0.01), sb.step(2, 0.03, 0.02, 0.01)
    assert ra["contact_force"] == pytest.approx(rb["contact_force"], rel=1e-12)
    assert np.allclose(a.u.x.array, b.u.x.array, rtol=1e-12, atol=1e-14)
    assert np.allclose(a.history.M.x.array, b.history.M.x.array, rtol=1e-12, atol=1e-14)


def test_the_step_grid_and_bounds(comm):
    c = StepController(build_model(_scene("time.k_max=0.1", "time.k_min=0.001"), comm))
    for k in (0.5, 0.0123, 1e-5):
        s = c._snap(k)
        assert 0.001 <= s <= 0.1 and (s <= k or s == 0.001)
        j = np.log2(s / 0.6) * 8
        assert s in (0.001, 0.1) or abs(j - round(j)) < 1e-9


def test_a_rejected_trial_that_lands_on_a_mark_is_retried_smaller(comm, monkeypatch):
    """load_cycle (8 x 8, tolerance 0.1, marks every 0.1) rejects its trial from 0.75 to the mark 0.8; the retry's
    landing stretched 0.9 of that step back to the whole of it, so the same trial was tried for ever. Every retry is
    now smaller than the trial it replaces, and the run ends (a cap on the trials turns a loop into a failure)."""
    tried, step = [], Stepper.step

    def counted(self, n, t, k, k_prev):
        tried.append((n, t, k))
        assert len(tried) < 3000, f"a loop of trials: {tried[-3:]}"
        return step(self, n, t, k, k_prev)

    monkeypatch.setattr(Stepper, "step", counted)
    marks = "output.times=[" + ", ".join(f"{0.1 * i:g}" for i in range(1, 10)) + "]"
    cfg = load(ROOT / "configs/load_cycle.toml", ["mesh.nx=8", "mesh.ny=8", "time.adaptive=true",
                                                   "time.tolerance=0.1", "time.k=0.01", marks])
    rows = list(levels(build_model(cfg, comm)))
    assert rows[-1]["t"] == pytest.approx(1.0, abs=1e-12)
    for (n0, _, k0), (n1, _, k1) in zip(tried, tried[1:]):
        assert n1 != n0 or k1 < k0  # a retry of level n is smaller than the trial before it
