"""What build_model (solver/run/model.py) builds from a scene's time scheme: the damage step, the history's rule,
the implicit trapezoid's term, and the memory source's kept strains, sized by the model at construction."""

import pytest
from conftest import ROOT

from solver.config import from_dict, load
from solver.physics.memory import PlaneStrainHistory, PronyHistory
from solver.run.model import build_model, time_scheme

SMALL = ["mesh.nx=3", "mesh.ny=3", "time.T=0.2", "time.k=0.1"]


@pytest.mark.parametrize("sets,rule,keep", [([], "left", 1), (["time.order=2"], "trapezoid_extrapolated", 2),
                                            (["memory.rule='trapezoid'"], "trapezoid", 1),
                                            (["material.model='plane_strain'", "time.order=2"],
                                             "trapezoid_extrapolated", 2)])
def test_the_history_takes_the_rule_and_the_source_its_kept_strains_from_the_scheme(comm, sets, rule, keep):
    cfg = load(ROOT / "configs/example1.toml", [*SMALL, *sets])
    model = build_model(cfg, comm)
    assert model.scheme == time_scheme(cfg) and model.scheme.memory_rule == rule
    main = model.history.main if isinstance(model.history, PlaneStrainHistory) else model.history
    assert isinstance(main, PronyHistory) and main.sum_rule.name == rule
    assert model.history.H.keep == keep  # u_n's strain, and u_{n-1}'s for the extrapolation
    # the implicit trapezoid's weight: the history's own constant, in the displacement form only for that rule
    assert (model.history.current_weight is not None) == (rule == "trapezoid")
    assert (model.u_prev is not None) == (rule == "trapezoid_extrapolated")


def test_a_scene_without_memory_builds_no_history_and_the_damage_of_its_scheme(comm):
    cfg = from_dict({"mesh": {"nx": 3, "ny": 3}, "time": {"T": 0.2, "k": 0.1, "order": 2}, "memory": {"kernel": "none"}})
    model = build_model(cfg, comm)
    assert model.history is None and model.u_prev is None
    assert type(model.damage).__name__ == "CNAB2Damage" and model.scheme.damage_scheme == "cnab2"
