"""solver/run/accuracy/time_error.py: the time part by step doubling, or by the run's step controller."""
import math

import numpy as np
import pytest
from conftest import ROOT

from solver.config import load
from solver.mesh.geometry import build
from solver.run.accuracy.scene import start_mesh, with_changes
from solver.run.accuracy.solves import PilotRun
from solver.run.accuracy.time_error import (
    FIRST_STEP_DIVISOR,
    N0,
    SAFETY,
    StepChoice,
    choose_step,
    controller_step,
    norms,
    restep,
    time_estimate,
)
from solver.run.model import build_model


@pytest.fixture
def model(comm):
    cfg = load(ROOT / "configs/example1.toml").replace({"time": {"T": 0.2, "k": 0.1}})
    cfg = with_changes(cfg, start_mesh(cfg, comm))
    return build_model(cfg, comm, build(comm, cfg.mesh, cfg.boundaries, cfg.dim))


def _runs(model, errors, levels=3):
    """Runs at k, k/2, k/4 whose u at every level is errors[i] times one field (zeta likewise): their error is
    errors[i] times that field's norm."""
    w = np.linspace(0.0, 1.0, model.u.x.array.size)
    z = np.linspace(1.0, 2.0, model.damage.zeta.x.array.size)
    out = []
    for i, e in enumerate(errors):
        n = (levels - 1) * 2**i + 1
        out.append(PilotRun(model, [j * 0.1 / 2**i for j in range(n)], [e * w] * n, [e * z] * n))
    return out, w, z


@pytest.mark.parametrize("order", [1, 2])
def test_step_doubling_recovers_the_order_and_the_error_of_the_finest_run(comm, model, order):
    errors = [(1.0 / 2**i) ** order for i in range(3)]  # e = k^p
    runs, w, z = _runs(model, errors)
    norm_u, norm_z = norms(model, comm)
    est = time_estimate(runs, 2, comm)
    assert est.rate == pytest.approx(order, rel=1e-12)
    assert est.error == pytest.approx(errors[2] * (norm_u(w) + norm_z(z)), rel=1e-12)
    assert np.array_equal(est.times, np.array(runs[1].t)) and len(est.profile) == len(runs[1].t)


def test_the_order_is_at_most_the_schemes(comm, model):
    runs, _, _ = _runs(model, [1.0, 1.0 / 4, 1.0 / 16])  # second order, judged for a first-order scheme
    assert time_estimate(runs, 1, comm).rate == 1.0


def test_no_difference_left_is_no_time_error(comm, model):
    runs, _, _ = _runs(model, [1.0, 1.0, 1.0])
    est = time_estimate(runs, 2, comm)
    assert est.error == 0.0 and est.rate == 2.0 and not est.profile.any()


def test_the_chosen_step_is_the_largest_within_its_share(comm):
    cfg = load(ROOT / "configs/example1.toml").replace({"time": {"T": 0.2}})
    cfg = with_changes(cfg, start_mesh(cfg, comm), {"discretization": {"u_degree": 1, "zeta_degree": 1}})
    geo = build(comm, cfg.mesh, cfg.boundaries, cfg.dim)
    share = 1e-4
    chosen = choose_step(cfg, comm, geo, 2, share, 1e-3, log=lambda *a: None)
    assert chosen.k0 == cfg.time.T / N0 and chosen.error <= SAFETY * share
    n = round(cfg.time.T / chosen.k)
    assert chosen.k == pytest.approx(cfg.time.T / n, rel=1e-12) and n >= N0
    if n > N0:  # the next larger step T / (n - 1) would not fit
        assert chosen.error * (n / (n - 1)) ** chosen.rate > SAFETY * share
    assert chosen.growth >= 1.0 and 0.0 <= chosen.largest_t <= cfg.time.T


def test_restep_takes_the_largest_step_within_the_budget():
    chosen = StepChoice(0.1, 1.0 / 46, 2.0, 4e-5, np.array([0.0, 0.5]), np.array([1e-5, 4e-5]), 1.0, 0.0)
    assert restep(chosen, 5e-5, 1.0) is chosen  # room enough: unchanged
    assert restep(chosen, 0.0, 1.0) is None
    smaller = restep(chosen, 3.6e-5, 1.0)
    n = round(1.0 / smaller.k)
    assert n == math.ceil(46 * (4e-5 / 3.6e-5) ** 0.5)  # error ~ k^2: the fewest steps within the budget
    assert smaller.error == pytest.approx(4e-5 * (46 / n) ** 2) and smaller.error <= 3.6e-5
    assert 4e-5 * (46 / (n - 1)) ** 2 > 3.6e-5  # one step fewer would not fit
    assert smaller.profile[-1] == pytest.approx(smaller.error)


def test_the_controllers_step_is_the_time_share_from_one_pilot(comm):
    cfg = load(ROOT / "configs/example1.toml").replace({"time": {"T": 0.2}})
    cfg = with_changes(cfg, start_mesh(cfg, comm), {"discretization": {"u_degree": 1, "zeta_degree": 1}})
    geo = build(comm, cfg.mesh, cfg.boundaries, cfg.dim)
    chosen = controller_step(cfg, comm, geo, 2, 1e-4, 1e-3, log=lambda *a: None)
    assert chosen.adaptive and chosen.error == 1e-4 and chosen.rate == 2.0
    assert chosen.k0 == cfg.time.T / N0 and chosen.k == chosen.k0 / FIRST_STEP_DIVISOR
    assert len(chosen.pilot.t) == N0 + 1  # one pilot at k0, not three
    assert chosen.growth >= 1.0 and 0.0 <= chosen.largest_t <= cfg.time.T
    # the growth is the one step doubling's first pilot measures (the same run)
    doubling = choose_step(cfg, comm, geo, 2, 1e-4, 1e-3, log=lambda *a: None)
    assert chosen.growth == pytest.approx(doubling.growth, rel=1e-10)


def test_restep_of_the_controller_makes_its_tolerance_the_budget():
    chosen = StepChoice(0.1, 0.0125, 2.0, 4e-5, np.array([0.0]), np.array([4e-5]), 1.0, 0.0, adaptive=True)
    assert restep(chosen, 5e-5, 1.0) is chosen and restep(chosen, -1e-6, 1.0) is None
    smaller = restep(chosen, 1e-5, 1.0)
    assert smaller.adaptive and smaller.error == 1e-5 and smaller.profile[-1] == pytest.approx(1e-5)
    assert smaller.k == pytest.approx(0.0125 * 0.25**0.5)  # the first step scaled as the error ~ k^order
