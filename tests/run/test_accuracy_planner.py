"""solver/run/accuracy/planner.py: what a tolerance chooses, the same on 2 ranks as on one, and the refusals.
Whether the achieved error meets the tolerance is measured by ``study tolerance`` against fine references; here
one small case checks it in the suite."""

import math

import pytest
from conftest import ROOT
from conftest import run_cli as cli
from mpi4py import MPI

from solver.config import load
from solver.errors import ToleranceError
from solver.run.accuracy import memory, planner
from solver.run.accuracy.planner import THETA_MAX, dorfler_fraction, plan

SCENE = ROOT / "configs/example1.toml"
SHORT = {"time": {"T": 0.2}}  # the paper's Example 1 over 0.2 s: quick, with memory and damage


def _short():
    return load(SCENE).replace(SHORT)


def _plan(comm, tol, accuracy=None):
    return plan(_short().replace({"accuracy": {"tolerance": tol, **(accuracy or {})}}), comm, log=lambda *a: None)


def test_the_dorfler_fraction_follows_the_distance_to_the_target():
    assert dorfler_fraction(0.5, 1.3) == 0.5  # near: the scene's theta
    assert dorfler_fraction(0.5, 1.05) == pytest.approx(2.0 * (1.0 - 1.0 / 1.05**2))  # a few per cent over: a little
    assert dorfler_fraction(0.5, 3.0) == pytest.approx(1.0 - 1.0 / 9.0)
    assert dorfler_fraction(0.5, 100.0) == THETA_MAX  # far: capped


def test_far_from_the_target_the_corners_are_refined_twice_in_a_round(comm, monkeypatch):
    """A Dörfler round with the estimate over CORNER_RATIO times its target refines the smallest set carrying
    CORNER_THETA of eta^2 (Example 1's singular corners, a few cells) twice and the rest once; the plan still meets
    its estimate, and on 2 ranks the plan is the serial one (the sets are marked by global thresholds)."""
    calls = []
    twice = planner.refine_twice

    def recorded(geo, cells, again=None):
        calls.append((comm.allreduce(len(cells)), None if again is None else comm.allreduce(len(again))))
        return twice(geo, cells, again)

    monkeypatch.setattr(planner, "refine_twice", recorded)
    p = _plan(comm, 1e-3)
    assert p.estimate.total <= 1e-3
    corners = [(n, m) for n, m in calls if m is not None]
    assert corners and all(0 < m < n for n, m in corners)
    if comm.size > 1:
        monkeypatch.setattr(planner, "refine_twice", twice)
        serial = _plan(MPI.COMM_SELF, 1e-3)
        assert (p.k, p.geo.num_cells()) == (serial.k, serial.geo.num_cells())
        assert math.isclose(p.estimate.total, serial.estimate.total, rel_tol=1e-8)


def test_a_scene_without_a_tolerance_is_not_planned(comm):
    with pytest.raises(ValueError, match="no accuracy.tolerance"):
        plan(_short(), comm, log=lambda *a: None)


def test_a_tolerance_chooses_p2_second_order_and_meets_its_own_estimate(comm):
    p = _plan(comm, 3e-3)
    assert p.degree == 2 and p.order == 2  # P2 converges at twice P1's rate in dofs on adapted meshes
    assert p.estimate.total <= 3e-3
    assert p.geo.num_cells() > 32  # adapted from the 4 x 4 start
    assert p.adaptation[-1].cells == p.geo.num_cells() and p.adaptation[-1].degree == 2
    tighter = _plan(comm, 1e-3)
    assert tighter.geo.num_cells() > p.geo.num_cells() and tighter.estimate.total <= 1e-3


def test_a_relative_tolerance_is_the_tolerance_times_the_strain_at_0(comm):
    from solver.run.accuracy.scene import degrees, with_changes
    from solver.run.accuracy.solves import solve_level0

    setup = planner.prepare(_short().replace({"accuracy": {"tolerance": 0.1, "relative": True}}), comm,
                            log=lambda *a: None)
    at_0 = solve_level0(with_changes(setup.base, degrees(2)), comm, setup.geo0)
    assert setup.tol == 0.1 * at_0.strain_norm and at_0.strain_norm > 0


def test_parallel_plan_equals_serial(comm):
    p = _plan(comm, 3e-3)
    serial = _plan(MPI.COMM_SELF, 3e-3) if comm.size > 1 else p
    assert (p.degree, p.order, p.k, p.geo.num_cells()) == (serial.degree, serial.order, serial.k,
                                                           serial.geo.num_cells())
    for key, value in p.estimate.as_dict().items():
        assert math.isclose(value, serial.estimate.as_dict()[key], rel_tol=1e-8, abs_tol=1e-14)


@pytest.mark.serial
@pytest.mark.slow
def test_the_achieved_error_is_below_the_tolerance():
    """Example 1 over 0.2 s at TOL 3e-3, against a P2 reference planned at 3e-4 with a 4x smaller step."""
    from studies.tolerance import Reference, tolerance_run

    ref = Reference.planned(_short(), 3e-4, 4, log=lambda *a: None)
    rec = tolerance_run(ref, _short(), 3e-3, log=lambda *a: None)
    assert 0.2 * 3e-3 <= rec["error"] <= 3e-3, rec


@pytest.mark.serial
def test_a_tolerance_run_restarts_on_the_same_mesh(tmp_path):
    """--restart plans again (the plan is deterministic), so the checkpoint fits the mesh and the last level
    is reproduced."""
    from solver.io.timeseries import TIMING_COLUMNS
    from solver.post.results import read_csv

    out = tmp_path / "o"
    args = ["run", "configs/example1.toml", "--tolerance", "1e-2", "--set", "time.T=0.2", "--set",
            "output.checkpoint_every=1", "--output", str(out), "--no-progress"]
    assert cli(args).returncode == 0
    first = read_csv(out / "timeseries.csv")
    res = cli([*args, "--restart"])
    assert res.returncode == 0, res.stderr
    again = read_csv(out / "timeseries.csv")
    assert len(again) == len(first)
    skip = {*TIMING_COLUMNS, "factorizations"}
    for key in first[-1]:
        if key not in skip:
            assert again[-1][key] == pytest.approx(first[-1][key], rel=1e-12, abs=1e-15), key


def test_a_tolerance_out_of_reach_names_the_users_tolerance_and_the_parts_target():
    with pytest.raises(ToleranceError) as info:
        _plan(MPI.COMM_WORLD, 1e-3, {"max_dofs": 300})
    err = info.value
    assert err.tolerance == 1e-3 and err.limit == "accuracy.max_dofs"
    assert err.target is not None and 0.0 < err.target < 1e-3 and err.estimate > err.target
    # refused from the prediction before any refinement, or, where it is within, by the refinement
    assert (err.dofs if err.predicted is None else err.predicted) > 300
    assert "accuracy.tolerance = 0.001 " in str(err)


def test_a_tolerance_far_out_of_reach_is_refused_from_the_prediction(monkeypatch):
    """1e-9 on Example 1 would refine to 10^6 dofs before anything said no; the rates measured on the start meshes
    predict the dofs it needs: refused there, with no mesh refined."""
    refined = []
    monkeypatch.setattr(planner.Planner, "_mesh", lambda self, *a: refined.append(a) or a[3:])
    with pytest.raises(ToleranceError) as info:
        _plan(MPI.COMM_WORLD, 1e-9)
    err = info.value
    assert not refined and err.limit == "accuracy.max_dofs" and err.predicted > 2_000_000
    assert "it would need about" in str(err)


def test_the_planner_never_grows_a_mesh_past_the_memory(monkeypatch):
    """The dof limit is the smaller of accuracy.max_dofs and what fits in the memory (here a machine made small by
    a huge cost per dof)."""
    monkeypatch.setattr(memory, "BYTES_PER_DOF", memory.BYTES_PER_DOF * 1e7)
    with pytest.raises(ToleranceError) as info:
        _plan(MPI.COMM_WORLD, 1e-3)
    assert info.value.limit.startswith("the memory (")


def test_where_the_indicator_grows_the_mesh_is_adapted_to_its_largest_level(monkeypatch, comm):
    """A growth over GROWTH_AT_0 (here made 0, so that any growth counts) judges u's mesh by runs to the level of
    largest indicator: the plan says so, and its space estimate is C eta of that level without a growth factor."""
    lines = []
    monkeypatch.setattr(planner, "GROWTH_AT_0", 0.0)
    p = plan(_short().replace({"accuracy": {"tolerance": 3e-3}}), comm, log=lines.append)
    assert any("level of largest eta" in line for line in lines), lines
    last = [r for r in p.adaptation if r.degree == p.degree][-1]
    assert p.estimate.space_u == last.estimate


def _controller_rows(p, comm):
    """The levels of the plan's run (the controller's rows: k, error_estimate)."""
    from solver.run.model import build_model
    from solver.run.stepper import levels

    return list(levels(build_model(p.config.replace({"output": {"xdmf": False}}), comm, p.geo)))


def test_the_steps_come_from_the_controller_where_asked(comm):
    """accuracy.time = adaptive: the run's controller with the time's share as its tolerance and the plan's first
    step; without damage any degree (P2 here); the controller estimates every step after the first two; the same plan
    on 2 ranks as on one."""
    no_damage = {"damage": {"enabled": False}, "accuracy": {"tolerance": 3e-3, "time": "adaptive"}}
    p = plan(_short().replace(no_damage), comm, log=lambda *a: None)
    cfg = p.config
    assert p.adaptive and cfg.time.adaptive and cfg.time.tolerance == p.estimate.time and cfg.time.k == p.k
    assert p.degree == 2 and p.estimate.total <= 3e-3 and p.summary()["time"] == "adaptive"
    serial = plan(_short().replace(no_damage), MPI.COMM_SELF, log=lambda *a: None) if comm.size > 1 else p
    assert (p.degree, p.geo.num_cells()) == (serial.degree, serial.geo.num_cells())
    # the first step and the tolerance follow the estimates (a kept mesh's room): equal up to round-off
    assert math.isclose(p.k, serial.k, rel_tol=1e-8) and math.isclose(p.estimate.time, serial.estimate.time, rel_tol=1e-8)
    rows = _controller_rows(p, comm)
    assert rows[-1]["t"] == pytest.approx(0.2) and all(math.isfinite(r["error_estimate"]) for r in rows)
    assert all(r["error_estimate"] > 0 for r in rows[3:])


def test_with_damage_the_controller_serves_degree_2(comm):
    """The controller's damage estimate works at P2 zeta (HRZ-lumped masses: solver.run.adaptive.lumped_mass), so a
    degree-2 plan with damage is a controlled run: its steps are estimated, none accepted blind."""
    p = _plan(comm, 1e-2, {"time": "adaptive", "degrees": [2]})
    assert p.degree == 2 and p.adaptive and p.config.damage.enabled
    rows = _controller_rows(p, comm)
    assert all(math.isfinite(r["error_estimate"]) for r in rows) and all(r["error_estimate"] > 0 for r in rows[3:])
