"""solver/run/accuracy/solves.py: the planner's solves and the strategies that judge u's mesh."""

import numpy as np
import pytest
from conftest import ROOT

from solver.config import load
from solver.mesh.geometry import build
from solver.physics.estimator import estimator_for
from solver.run.accuracy.scene import degrees, start_mesh, step, with_changes
from solver.run.accuracy.solves import (
    AtLargestLevel,
    AtLevel0,
    displacement_dofs,
    pilot_run,
    solve_largest_level,
    solve_level0,
)


@pytest.fixture
def scene_geo(comm):
    cfg = load(ROOT / "configs/example1.toml").replace({"time": {"T": 0.2, "k": 0.05}})
    cfg = with_changes(cfg, start_mesh(cfg, comm), degrees(1))
    return cfg, build(comm, cfg.mesh, cfg.boundaries, cfg.dim)


def test_level0_is_the_elastic_problems_and_carries_its_indicator(comm, scene_geo):
    cfg, geo = scene_geo
    lv = solve_level0(cfg, comm, geo)
    assert lv.model.damage is None and lv.model.history is None  # level 0 does not touch memory and damage
    assert lv.indicator == pytest.approx(estimator_for(lv.model).total(), rel=1e-12)
    assert lv.indicator == pytest.approx(np.sqrt(comm.allreduce(lv.cell_indicators.sum())), rel=1e-14)
    assert lv.dofs == displacement_dofs(lv.model) == 2 * 5 * 5  # P1 on 4 x 4 squares: 5 x 5 nodes, 2 components
    assert lv.strain_norm > 0


def test_the_largest_level_is_the_pilots_largest_indicator(comm, scene_geo):
    cfg, geo = scene_geo
    largest = solve_largest_level(cfg, comm, geo)
    pilot = pilot_run(cfg, comm, geo, indicator=True)
    assert len(pilot.t) == len(pilot.u) == len(pilot.zeta) == len(pilot.indicator) == 5
    assert largest.indicator == pytest.approx(max(pilot.indicator), rel=1e-12)
    assert largest.strain_norm is None


def test_the_growth_factor_is_at_least_one_at_level0_and_one_at_the_largest_level(scene_geo):
    cfg, _ = scene_geo
    assert AtLevel0(cfg, 0.8).factor == 1.0 and AtLevel0(cfg, 1.7).factor == 1.7
    assert AtLevel0(cfg, 0.8).growth == 0.8  # the degree's prediction uses the growth as measured
    assert AtLargestLevel(with_changes(cfg, step(0.1))).factor == 1.0 == AtLargestLevel(cfg).growth


def test_a_probe_solves_with_the_degree_asked(comm, scene_geo):
    cfg, geo = scene_geo
    lv = AtLevel0(cfg, 1.0).solve(2, comm, geo)
    assert lv.model.cfg.discretization.u_degree == 2 == lv.model.cfg.discretization.zeta_degree
    assert lv.indicator == pytest.approx(solve_level0(with_changes(cfg, degrees(2)), comm, geo).indicator, rel=1e-12)


def test_a_level0_solve_started_from_the_coarser_mesh_finds_the_same_solution_in_fewer_steps(comm):
    from solver.mesh.adapt import refine_uniformly

    cfg = with_changes(load(ROOT / "configs/example1.toml"), {"mesh": {"nx": 8, "ny": 8}}, degrees(2))
    geo = build(comm, cfg.mesh, cfg.boundaries, cfg.dim)
    coarse = solve_level0(cfg, comm, geo)
    fine = refine_uniformly(geo)
    cold = solve_level0(cfg, comm, fine)
    warm = solve_level0(cfg, comm, fine, coarse.model)
    assert warm.indicator == pytest.approx(cold.indicator, rel=1e-6)
    assert np.allclose(warm.model.u.x.array, cold.model.u.x.array, atol=1e-9 * np.abs(cold.model.u.x.array).max())
    assert warm.iterations < cold.iterations
