"""The registry of displacement methods (solver/solvers/methods.py): each scene method is built once, where it
applies, else what it names instead; auto composes Newton and the method that takes a failed level over."""

import numpy as np
import pytest
from conftest import ROOT

from solver.config import METHODS as SCENE_METHODS
from solver.config import from_dict, load
from solver.errors import ConfigError
from solver.run.model import build_model
from solver.solvers.auto import NEWTON_ITERATIONS, AutoSolver
from solver.solvers.condensed import CondensedNewtonSolver
from solver.solvers.energy_newton import EnergyNewtonSolver
from solver.solvers.fixed_point import FixedPointSolver, PenaltyDualitySolver
from solver.solvers.method import DisplacementMethod
from solver.solvers.methods import METHODS, MethodContext, resolve
from solver.solvers.newton import NewtonSolver

SMALL = ["time.T=0.02", "time.k=0.02", "output.xdmf=false"]


def _model(comm, method: str, extra=()):
    return build_model(load(ROOT / "configs" / "hard.toml", [*SMALL, f"solver.method='{method}'", *extra]), comm)


def test_every_scene_method_is_registered():
    assert set(METHODS) == set(SCENE_METHODS)


@pytest.mark.parametrize("method,extra,built", [
    ("newton", (), NewtonSolver),
    ("newton_energy", (), EnergyNewtonSolver),
    ("newton_condensed", (), CondensedNewtonSolver),
    ("fixed_point", (), FixedPointSolver),
    ("penalty_duality", (), PenaltyDualitySolver),
    # no factorization of K to reuse: newton_condensed's instead
    ("newton_condensed", ("solver.linear='iterative'",), EnergyNewtonSolver),
    # the implicit memory term has no energy: newton_energy's instead, and so newton_condensed's
    ("newton_energy", ("memory.rule='trapezoid'",), NewtonSolver),
    ("newton_condensed", ("memory.rule='trapezoid'",), NewtonSolver),
])
def test_each_method_is_built_where_it_applies_else_its_instead(comm, method, extra, built):
    assert type(_model(comm, method, extra).mech.solver) is built


def test_without_contact_the_method_is_newton(comm):
    """No contact part: the problem is linear, whatever solver.method says."""
    cfg = from_dict({
        "mesh": {"nx": 2, "ny": 2},
        "boundary": {"left": {"role": "clamped"}, "right": {"role": "traction", "traction": [1.0, 0.0]}},
        "memory": {"kernel": "none"}, "damage": {"enabled": False},
        "time": {"T": 0.1, "k": 0.1}, "solver": {"method": "newton_condensed"},
    })
    assert type(build_model(cfg, comm).mech.solver) is NewtonSolver


def test_auto_composes_newton_and_the_takeover_on_one_core(comm):
    """Newton with at most NEWTON_ITERATIONS a level and no damped fallback; newton_condensed on the same SNES and
    KSP, to the scene's max_it."""
    auto = _model(comm, "auto").mech.solver
    assert isinstance(auto, AutoSolver) and isinstance(auto.takeover, CondensedNewtonSolver)
    assert auto.takeover.core is auto.newton.core is auto.core
    assert not auto.newton.fallback.allowed
    max_it = load(ROOT / "configs" / "hard.toml").solver.max_it
    assert auto.newton.core.test.max_it == min(max_it, NEWTON_ITERATIONS)
    assert auto.takeover.test.max_it == max_it


@pytest.mark.parametrize("extra,takeover", [
    (("solver.linear='iterative'",), EnergyNewtonSolver),
    (("memory.rule='trapezoid'",), None),
    (("solver.newton_fallback=false",), None),
])
def test_auto_hands_over_to_what_applies(comm, extra, takeover):
    auto = _model(comm, "auto", extra).mech.solver
    assert (type(auto.takeover) if auto.takeover is not None else None) is takeover
    if takeover is None:  # Newton alone, with the scene's limit
        assert auto.newton.core.test.max_it == load(ROOT / "configs" / "hard.toml").solver.max_it


def test_a_point_method_needs_the_points(comm):
    """fixed_point and penalty_duality work on the contact term at its points (2-D): nothing instead."""
    model = _model(comm, "newton")
    mech = model.mech
    ctx = MethodContext(mech.problem, mech.settings, comm, model.geo, mech.physics.parts, None)
    assert resolve("newton_condensed", ctx) == "newton_condensed"
    for name in ("fixed_point", "penalty_duality"):
        with pytest.raises(ConfigError, match=name):
            resolve(name, ctx)


def test_what_a_checkpoint_carries_is_declared(comm):
    """A method carries nothing by default; newton_condensed its predictor, auto the level it switched at."""

    class Plain(DisplacementMethod):
        def solve(self, scale):
            raise NotImplementedError

    plain = Plain()
    assert plain.state() == {} and plain.scalars() == {} and plain.fallbacks == 0
    with pytest.raises(KeyError):
        plain.restore("predictor", np.zeros(1))
    assert set(_model(comm, "newton").mech.scalars()) == {"c_norm", "reuse"}
    auto = _model(comm, "auto").mech
    assert set(auto.state()) == {"F_last", "b", "predictor"}
    assert set(auto.scalars()) == {"c_norm", "reuse", "switched_at", "levels", "direct", "direct_levels"}


def test_a_method_built_where_it_does_not_apply_is_refused(comm):
    """The classes check their requirement (the registry builds their instead): newton_energy without an energy,
    newton_condensed with an iterative solver."""
    newton = _model(comm, "newton_energy", ["memory.rule='trapezoid'"]).mech.solver
    with pytest.raises(ConfigError, match="newton_energy"):
        EnergyNewtonSolver(newton.core)
    model = _model(comm, "newton_condensed", ["solver.linear='iterative'"])
    energy = model.mech.solver
    with pytest.raises(ConfigError, match="newton_condensed"):
        CondensedNewtonSolver(energy, MethodContext(model.mech.problem, model.mech.settings, comm, model.geo,
                                                    model.mech.physics.parts, None).contact_dofs,
                              model.mech.settings.linear)
