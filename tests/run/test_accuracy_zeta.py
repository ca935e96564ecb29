"""solver/run/accuracy/zeta.py: the damage's space error from nested meshes, and its bound on planned meshes."""

import math

import pytest
from conftest import ROOT
from mpi4py import MPI

from solver.config import load
from solver.mesh.adapt import refine_uniformly
from solver.run.accuracy import planner
from solver.run.accuracy.zeta import (
    ZETA_EXPONENT_MAX,
    ZETA_EXPONENT_MIN,
    ZetaRuns,
    exponent_range,
    observed_exponent,
    zeta_difference,
    zeta_space,
)

SCENE = ROOT / "configs/example1.toml"


def _short_plan(comm, tol, log=lambda *a: None, changes=None):
    scene = load(SCENE).replace({"time": {"T": 0.2}, **(changes or {})})
    return planner.plan(scene.replace({"accuracy": {"tolerance": tol}}), comm, log=log)


@pytest.mark.parametrize("s", [0.55, 0.7, 0.9])
def test_the_observed_exponent_recovers_a_power_law(s):
    cells = (32, 212, 938)  # uneven ratios, as an adapted sequence gives
    e = [3.0 * n**-s for n in cells]
    assert observed_exponent(cells, e[0] - e[1], e[1] - e[2]) == pytest.approx(s, rel=1e-9)
    # the estimate it gives on the finest mesh is then that mesh's error
    assert (e[1] - e[2]) / ((cells[2] / cells[1]) ** s - 1.0) == pytest.approx(e[2], rel=1e-9)


def test_the_observed_exponent_is_clamped():
    cells = (50, 200, 800)
    slow = [n**-0.2 for n in cells]  # slower than a rate 1 in h: the estimate assumes rate 1 (and says less)
    fast = [n**-1.5 for n in cells]  # faster than P1 can converge: taken as rate 2
    assert observed_exponent(cells, slow[0] - slow[1], slow[1] - slow[2]) == ZETA_EXPONENT_MIN
    assert observed_exponent(cells, fast[0] - fast[1], fast[1] - fast[2]) == ZETA_EXPONENT_MAX[1]
    assert observed_exponent(cells, 1e-3, 0.0) == ZETA_EXPONENT_MAX[1]  # no difference left on the finest pair
    assert observed_exponent(cells, math.nan, 1e-3) == ZETA_EXPONENT_MIN
    # P2 zeta may converge at rate 3 in h (s = 1.5): the same rate 1.5 is recovered, not clamped
    assert observed_exponent(cells, fast[0] - fast[1], fast[1] - fast[2], 2) == pytest.approx(1.5, rel=1e-9)
    faster = [n**-2.0 for n in cells]
    assert observed_exponent(cells, faster[0] - faster[1], faster[1] - faster[2], 2) == ZETA_EXPONENT_MAX[2]


def test_without_damage_nothing_is_run(comm):
    scene = load(SCENE).replace({"damage": {"enabled": False}})
    runs = ZetaRuns()
    z = zeta_space(scene, comm, None, (), runs)
    assert z.bound == 0.0 and z.finer is None


def test_runs_are_made_once_per_mesh_and_step(comm):
    from solver.mesh.geometry import build
    from solver.run.accuracy.scene import start_mesh, with_changes

    scene = load(SCENE).replace({"time": {"T": 0.2, "k": 0.1}})
    scene = with_changes(scene, start_mesh(scene, comm))
    geo = build(comm, scene.mesh, scene.boundaries, scene.dim)
    runs = ZetaRuns()
    first = runs.on(scene, comm, [geo])
    assert runs.on(scene, comm, [geo])[0] is first[0]
    assert len(first[0].zeta) == 3  # levels 0, 1, 2
    assert zeta_difference(first[0], first[0], comm) < 1e-14  # a mesh against itself: round-off of the basis at its nodes


def test_the_zeta_estimate_bounds_the_difference_to_a_much_finer_mesh(monkeypatch):
    """zeta's space estimate on the chosen mesh (three nested meshes, observed exponent) is at least the
    difference to that mesh refined uniformly twice (16 times the cells), at the same step."""
    seen = []
    monkeypatch.setattr(planner, "zeta_space", lambda *a, **k: seen.append(zeta_space(*a, **k)) or seen[-1])
    p = _short_plan(MPI.COMM_WORLD, 3e-3)
    fine = p.geo
    for _ in range(2):
        fine = refine_uniformly(fine)
    at = p.config.replace({"time": {"k": 0.02}})
    coarse_run, fine_run = ZetaRuns().on(at, MPI.COMM_WORLD, [p.geo, fine])
    measured = zeta_difference(coarse_run, fine_run, MPI.COMM_WORLD)
    assert seen and measured > 0.0
    assert seen[-1].bound >= measured, (seen[-1].bound, measured)
    assert p.estimate.space_zeta == seen[-1].bound


def test_where_zetas_part_leaves_room_u_is_adapted_on_instead_of_refining_uniformly(monkeypatch):
    """Example 1 with mu = 1e-3 at TOL 3e-3: on the mesh adapted for u, zeta's part is over its 30% of the space
    share and the sum over it; a Dörfler step for u (not a uniform refinement, which gave 1,296 cells) makes room.
    zeta's bound on the new mesh is its bound on the coarser one plus their measured difference, and it is at least
    the difference to the new mesh refined uniformly twice (16 times the cells)."""
    lines, seen, meshes = [], [], []

    def spy(*a, **k):
        meshes.append(a[2])  # the mesh zeta's part is estimated on
        seen.append(zeta_space(*a, **k))
        return seen[-1]

    monkeypatch.setattr(planner, "zeta_space", spy)
    monkeypatch.setattr(planner, "ZETA_SHARE", 0.2)  # u's first mesh leaves zeta 20% of the space share: too little
    p = planner.plan(load(SCENE).replace({"boundary": {"bottom": {"mu": 1e-3}}, "accuracy": {"tolerance": 3e-3}}),
                     MPI.COMM_WORLD, log=lines.append)
    assert any(line.startswith("  a Dörfler step for u") and line.endswith("taken") for line in lines), lines
    assert not any(r.uniform for r in p.adaptation) and p.geo.num_cells() < 1296
    coarse = meshes[-1]  # the mesh adapted for u (before it, zeta's part was measured on a coarser one, too large)
    at_k0 = p.config.replace({"time": {"k": 0.1}})
    runs = ZetaRuns().on(at_k0, MPI.COMM_WORLD, [coarse, p.geo])
    step = zeta_difference(*runs, MPI.COMM_WORLD)
    assert p.estimate.space_zeta == pytest.approx(seen[-1].bound + step, rel=1e-12)
    fine = p.geo
    for _ in range(2):
        fine = refine_uniformly(fine)
    runs = ZetaRuns().on(at_k0, MPI.COMM_WORLD, [p.geo, fine])
    measured = zeta_difference(*runs, MPI.COMM_WORLD)
    assert 0.0 < measured <= p.estimate.space_zeta, (measured, p.estimate)
    assert p.estimate.total <= 3e-3


def test_where_zetas_part_leaves_no_room_the_mesh_is_refined_uniformly(monkeypatch, comm):
    """With no room left to zeta's part (ZETA_SHARE and ROOM_ZETA_MAX 0), the space parts are fitted by uniform
    refinement: a record marked uniform, with four times the cells of the mesh before it, and the sum within TOL."""
    monkeypatch.setattr(planner, "ZETA_SHARE", 0.0)
    monkeypatch.setattr(planner, "ROOM_ZETA_MAX", 0.0)
    p = _short_plan(comm, 3e-3, changes={"boundary": {"bottom": {"mu": 1e-3}}})
    uniform = [i for i, r in enumerate(p.adaptation) if r.uniform]
    assert uniform, p.adaptation
    i = uniform[0]
    assert p.adaptation[i].cells == 4 * p.adaptation[i - 1].cells and p.adaptation[i].geo is None
    assert p.geo.num_cells() == p.adaptation[-1].cells and p.estimate.total <= 3e-3


def test_in_3d_the_exponents_are_the_same_rates_in_h():
    """cells ~ h^-3 on tetrahedra: a rate of 1 to q + 1 in h is s = 1/3 to (q + 1)/3 over the cells."""
    assert exponent_range(1, 3) == pytest.approx((1 / 3, 2 / 3)) and exponent_range(2, 3) == pytest.approx((1 / 3, 1.0))
    cells = (400, 3200, 25600)
    e = [n ** -0.8 for n in cells]  # a rate of 2.4 in h
    assert observed_exponent(cells, e[0] - e[1], e[1] - e[2], 1, 3) == pytest.approx(2 / 3)  # clamped for P1
    assert observed_exponent(cells, e[0] - e[1], e[1] - e[2], 2, 3) == pytest.approx(0.8, rel=1e-9)
    slow = [n ** -0.2 for n in cells]  # slower than 1 in h: clamped to 1/3
    assert observed_exponent(cells, slow[0] - slow[1], slow[1] - slow[2], 2, 3) == pytest.approx(1 / 3)


def test_a_zeta_run_starts_from_the_t0_solution_on_its_mesh(comm):
    """ZetaRuns.start_from: level 0 of a run on that mesh starts from the t = 0 problem's solution there (the same
    problem): the same run, level 0 in fewer Newton iterations than from zero; another mesh starts from zero."""
    import numpy as np

    from solver.mesh.geometry import build
    from solver.run.accuracy.scene import degrees, with_changes
    from solver.run.accuracy.solves import solve_level0

    cfg = with_changes(load(SCENE), {"time": {"T": 0.2, "k": 0.1}, "mesh": {"nx": 8, "ny": 8}}, degrees(2))
    geo = build(comm, cfg.mesh, cfg.boundaries, cfg.dim)
    at_0 = solve_level0(cfg, comm, geo)
    runs = ZetaRuns()
    runs.start_from(geo, 2, at_0.model.u.x.array.copy())
    warm = runs.on(cfg, comm, [geo])[0]
    cold = ZetaRuns().on(cfg, comm, [geo])[0]
    assert warm.newton[0] < cold.newton[0]
    scale = np.abs(cold.u[-1]).max()
    for a, b in zip(warm.u, cold.u):
        assert np.allclose(a, b, atol=1e-8 * scale)
    for a, b in zip(warm.zeta, cold.zeta):
        assert np.allclose(a, b, atol=1e-10)
    other = refine_uniformly(geo)  # no start given there: from zero, as before
    assert runs.on(cfg, comm, [other])[0].newton[0] == ZetaRuns().on(cfg, comm, [other])[0].newton[0]
