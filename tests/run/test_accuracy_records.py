"""solver/run/accuracy/records.py: a plan's records, and what a tolerance run writes of them."""

import json

import numpy as np
import pytest
from conftest import run_cli as cli

from solver.config import load
from solver.run.accuracy.records import ErrorEstimate, MeshRecord, Plan


def test_the_estimate_is_the_sum_of_its_parts():
    e = ErrorEstimate(space_u=1e-3, space_zeta=2e-4, time=5e-5)
    assert e.total == 1e-3 + 2e-4 + 5e-5
    assert e.as_dict() == {"space_u": 1e-3, "space_zeta": 2e-4, "time": 5e-5}


def test_a_mesh_record_writes_eta_and_says_uniform_only_when_it_is():
    adapted = MeshRecord(2, 86, 398, 0.5, 7e-3, geo=object())
    assert adapted.summary() == {"degree": 2, "cells": 86, "dofs": 398, "eta": 0.5, "estimate": 7e-3}
    assert list(adapted.summary()) == ["degree", "cells", "dofs", "eta", "estimate"]  # plan.json's order
    assert MeshRecord(2, 344, 1500, 0.2, 3e-3, uniform=True).summary()["uniform"] is True
    assert MeshRecord(2, 86, 398, 0.5, 7e-3, seconds=0.25).summary()["seconds"] == 0.25  # the round's time


def test_the_time_error_is_the_profiles_last_level_at_or_before_t():
    plan = Plan(1e-3, 2, 2, 0.1, None, {}, ErrorEstimate(0, 0, 0), 1.0, 1.0, 2.0,
                (np.array([0.0, 0.1, 0.2]), np.array([0.0, 1e-4, 3e-4])), (), 0.0, None)
    assert plan.time_error(0.0) == 0.0
    assert plan.time_error(0.1) == 1e-4  # a level's own time, to round-off
    assert plan.time_error(0.1 - 1e-15) == 1e-4
    assert plan.time_error(0.15) == 1e-4 and plan.time_error(0.3) == 3e-4
    empty = Plan(1e-3, 2, 2, 0.1, None, {}, ErrorEstimate(0, 0, 0), 1.0, 1.0, 2.0,
                 (np.array([]), np.array([])), (), 0.0, None)
    assert empty.time_error(0.5) == 0.0


@pytest.mark.serial
@pytest.mark.parametrize("nproc", [1, 2])
def test_a_tolerance_run_records_what_it_chose(tmp_path, nproc):
    from solver.post.results import read_csv

    out = tmp_path / "o"
    res = cli(["run", "configs/example1.toml", "--tolerance", "1e-2", "--set", "time.T=0.2", "--output", str(out),
               "--no-progress"], nproc)
    assert res.returncode == 0, res.stderr
    info = json.loads((out / "plan.json").read_text())
    cfg = load(out / "config.toml")
    assert cfg.discretization.u_degree == info["u_degree"] and cfg.time.k == info["k"]
    assert cfg.discretization.zeta_degree == info["zeta_degree"] == info["u_degree"]  # zeta's degree follows u's
    assert cfg.time.order == info["order"] and cfg.accuracy.tolerance == 1e-2
    assert set(info["estimate"]) == {"space_u", "space_zeta", "time"}
    assert info["adaptation"][-1]["cells"] == info["cells"] and "geo" not in info["adaptation"][-1]
    assert (out / "mesh.xdmf").exists()
    rows = read_csv(out / "timeseries.csv")
    space, tim = np.array([r["est_space"] for r in rows]), np.array([r["est_time"] for r in rows])
    assert np.all(space + tim <= 1e-2) and np.all(space > 0)
    assert "estimated error" in res.stderr and "for tolerance 1.000e-02" in res.stderr
