"""solver/run/accuracy/ingredients.py: each ingredient's change of the answer, and what accuracy.simplify leaves out."""

import math

import pytest
from conftest import ROOT

from solver.config import load
from solver.run.accuracy import ingredients, planner
from solver.run.accuracy.ingredients import Ingredient, simplified, without

SCENE = ROOT / "configs/example1.toml"


def test_without_leaves_out_one_ingredient():
    cfg = load(SCENE)
    assert without(cfg, "memory").memory.kernel == "none" and without(cfg, "memory").damage.enabled
    assert not without(cfg, "damage").damage.enabled and without(cfg, "damage").memory.kernel == cfg.memory.kernel
    assert without(cfg, "truncation").memory.L > 1e100
    first = without(cfg.replace({"time": {"order": 2}}), "order")
    assert first.time.order == 1 and first.memory.rule == "left"  # the rule resolved for order 1 again


def test_simplify_leaves_out_the_smallest_while_their_sum_stays_within_its_fraction():
    tol = 1.0
    f = ingredients.SIMPLIFY_FRACTION
    changes = [Ingredient("memory", 0.6 * f, ""), Ingredient("damage", 0.3 * f, ""), Ingredient("order", 0.0, "")]
    out, total = simplified(changes, tol)
    assert {i.name for i in out if i.dropped} == {"damage", "memory"} and total == pytest.approx(0.9 * f)
    changes = [Ingredient("memory", 0.8 * f, ""), Ingredient("damage", 0.3 * f, ""), Ingredient("order", 0.0, "")]
    out, total = simplified(changes, tol)
    assert [i.name for i in out if i.dropped] == ["damage"]  # memory on top would pass f
    out, total = simplified([Ingredient("memory", math.nan, ""), Ingredient("truncation", 0.0, "")], tol)
    assert total == 0.0 and not any(i.dropped for i in out)  # unmeasured or not droppable: kept


def test_a_plan_reports_every_ingredient_and_simplify_plans_without_those_it_leaves_out(comm, monkeypatch):
    tol = 0.3
    scene = load(SCENE).replace({"time": {"T": 0.2}, "accuracy": {"tolerance": tol}})
    full = planner.plan(scene, comm, log=lambda *a: None)
    names = {i.name for i in full.ingredients}
    assert {"memory", "damage", "truncation", "order"} <= names
    assert ("degree" in names) == (full.degree == 2)  # P2 over P1 where P2 was chosen
    assert all(i.change >= 0.0 for i in full.ingredients) and not any(i.dropped for i in full.ingredients)
    summary = full.summary()
    assert set(summary["ingredients"]) == names and summary["left_out"] == []
    changes = {i.name: i.change for i in full.ingredients}
    both = changes["memory"] + changes["damage"]
    assert 0.0 < both < 0.5 * tol, changes
    # a fraction just large enough to leave out both memory and damage
    fraction = 1.01 * both / tol
    monkeypatch.setattr(ingredients, "SIMPLIFY_FRACTION", fraction)
    monkeypatch.setattr(planner, "SIMPLIFY_FRACTION", fraction)
    lines = []
    p = planner.plan(scene.replace({"accuracy": {"simplify": True}}), comm, log=lines.append)
    dropped = {i.name for i in p.ingredients if i.dropped}
    assert dropped == {"memory", "damage"}, p.ingredients
    assert p.config.memory.kernel == "none" and not p.config.damage.enabled
    left = sum(i.change for i in p.ingredients if i.dropped)
    assert left == pytest.approx(both, rel=1e-9)  # the same pilots
    assert p.tolerance == tol and p.estimate.model == pytest.approx(left)
    assert p.config.accuracy.tolerance == pytest.approx(tol - left)  # planned for what the ingredients left
    assert p.estimate.total <= tol
    assert any(line.startswith("accuracy.simplify: left out") for line in lines)


def test_a_simplified_plan_reuses_the_full_scenes_pilots(comm, monkeypatch):
    """One ingredient left out: the simplified scene's step doubling starts from the run without it (made for the
    report) and its ingredients are not measured again: 1 + 4 pilot runs of the full scene and 2 of the simplified
    one's step doubling (13 before: both scenes' step doubling and ingredients whole). The report is the full
    scene's changes, the order's at the simplified plan's step."""
    from solver.run.accuracy import time_error

    tol = 0.3
    scene = load(SCENE).replace({"time": {"T": 0.2}, "accuracy": {"tolerance": tol}})
    whole = planner.plan(scene, comm, log=lambda *a: None)
    full = {i.name: i.change for i in whole.ingredients}
    smallest = min(("memory", "damage"), key=lambda n: full[n])
    fraction = 1.01 * full[smallest] / tol  # only the smallest fits
    monkeypatch.setattr(ingredients, "SIMPLIFY_FRACTION", fraction)
    monkeypatch.setattr(planner, "SIMPLIFY_FRACTION", fraction)
    made = []
    for module in (time_error, ingredients):
        real = module.pilot_run
        monkeypatch.setattr(module, "pilot_run", lambda *a, real=real, **k: made.append(1) or real(*a, **k))
    p = planner.plan(scene.replace({"accuracy": {"simplify": True}}), comm, log=lambda *a: None)
    assert {i.name for i in p.ingredients if i.dropped} == {smallest}
    assert len(made) == 7
    got = {i.name: i for i in p.ingredients}
    assert got[smallest].change == pytest.approx(full[smallest], rel=1e-9)
    assert got["order"].change == pytest.approx(full["order"] * p.k / whole.k, rel=1e-9)
    assert p.estimate.total <= tol
