"""The time scheme decided once (solver/config/time.py: TimeScheme) and carried out per order (solver/run/scheme.py)."""

import ast
from pathlib import Path

import pytest
from conftest import ROOT

from solver.config import from_dict
from solver.config.time import TimeScheme, memory_rule
from solver.run.model import build_model
from solver.run.scheme import FirstOrderScheme, SecondOrderScheme, level_scheme

SCENE = {"mesh": {"nx": 4, "ny": 4}, "time": {"T": 0.2, "k": 0.1}}


@pytest.mark.parametrize("order,kernel,rule,want", [
    (1, "constant", "auto", "left"), (2, "constant", "auto", "trapezoid_extrapolated"),
    (2, "exponential", "auto", "trapezoid_extrapolated"), (2, "tabulated", "auto", "trapezoid_extrapolated"),
    (2, "none", "auto", "left"), (1, "constant", "trapezoid", "trapezoid"),
    (2, "constant", "trapezoid", "trapezoid"), (1, "exponential", "trapezoid_extrapolated", "trapezoid_extrapolated")])
def test_the_memory_rule_follows_the_order_unless_named(order, kernel, rule, want):
    assert memory_rule(order, kernel, rule) == want


@pytest.mark.parametrize("order,kernel,rule,damage,damage_scheme,want", [
    (1, "constant", "auto", True, "explicit", ("left", "explicit", False)),
    (1, "constant", "auto", True, "semi_implicit", ("left", "semi_implicit", False)),
    (2, "constant", "auto", True, "explicit", ("trapezoid_extrapolated", "cnab2", True)),
    (2, "constant", "auto", False, "explicit", ("trapezoid_extrapolated", "cnab2", True)),  # M_1 to correct
    (2, "constant", "trapezoid", False, "explicit", ("trapezoid", "cnab2", False)),  # nothing to correct
    (2, "none", "auto", False, "explicit", ("left", "cnab2", False)),
    (2, "none", "auto", True, "explicit", ("left", "cnab2", True)),  # zeta_1 to correct
    (1, "exponential", "trapezoid_extrapolated", True, "explicit", ("trapezoid_extrapolated", "explicit", False)),
])
def test_the_scheme_decides_rule_damage_step_and_start(order, kernel, rule, damage, damage_scheme, want):
    s = TimeScheme.decide(order, kernel, rule, damage, damage_scheme)
    assert (s.order, s.memory_rule, s.damage_scheme, s.heun_start) == (order, *want)


@pytest.mark.parametrize("order,cls", [(1, FirstOrderScheme), (2, SecondOrderScheme)])
def test_the_model_carries_its_scheme_and_the_steps_follow_it(comm, order, cls):
    model = build_model(from_dict({**SCENE, "time": {**SCENE["time"], "order": order}}), comm)
    assert model.scheme == TimeScheme.decide(order, "constant", model.cfg.memory.rule, True, "explicit")
    steps = level_scheme(model, model.scheme)
    assert type(steps) is cls and steps.scheme is model.scheme


def test_a_second_order_scheme_without_a_start_solves_level_1_once(comm):
    """Order 2 with the implicit trapezoid and no damage: nothing needs two past levels, so no Heun corrector."""
    from solver.run.stepper import Stepper

    cfg = from_dict({**SCENE, "time": {**SCENE["time"], "order": 2}, "memory": {"rule": "trapezoid"},
                     "damage": {"enabled": False}})
    model = build_model(cfg, comm)
    assert not model.scheme.heun_start and model.u_prev is None
    with_start = build_model(from_dict({**SCENE, "time": {**SCENE["time"], "order": 2}}), comm)
    assert with_start.scheme.heun_start
    calls = []
    model.mech.solve, solve = (lambda t: calls.append(t) or solve(t)), model.mech.solve
    stepper = Stepper(model)
    stepper.step(0)
    stepper.step(1)
    assert calls == [0.0, 0.1]


def _imports(module: Path) -> set[str]:
    tree = ast.parse(module.read_text())
    return {n.module for n in ast.walk(tree) if isinstance(n, ast.ImportFrom) and n.module} | {
        a.name for n in ast.walk(tree) if isinstance(n, ast.Import) for a in n.names}


def test_the_model_and_the_scheme_do_not_import_each_other():
    run = ROOT / "solver" / "run"
    assert not any(m.startswith("solver.run.model") for m in _imports(run / "scheme.py"))
    assert not any(m.startswith("solver.run.scheme") for m in _imports(run / "model.py"))
