"""study tolerance: a scene's own reference (--scene-ref-tol, --scene-ref-uniform), how it is kept and stated in the
output."""

from __future__ import annotations

import csv
import json
import subprocess

import pytest
from conftest import ROOT, solver_cmd

from studies.tolerance import _kept, _write, scene_ref_tol, scene_ref_uniform


def test_scene_ref_tol_parses_name_and_tolerance():
    assert scene_ref_tol("hard=3e-4") == ("hard", 3e-4)
    assert scene_ref_tol("example1-gap0.02=0.0002") == ("example1-gap0.02", 2e-4)


@pytest.mark.parametrize("item,word", [("nosuch=1e-4", "NAME=TOL"), ("hard", "NAME=TOL"), ("hard=0", "between"),
                                       ("hard=1", "between"), ("hard=nan", "between"), ("hard=abc", "between")])
def test_scene_ref_tol_refuses_bad_items(item, word):
    with pytest.raises(ValueError, match=word):
        scene_ref_tol(item)


def _scene(ref_tol=None, failure=False):
    ref = {"failure": "out of reach"} if failure else {"cells": 10, "dofs": 50, "k": 0.025, "estimate": 2e-4,
                                                       "seconds": 1.0, "second_vs_first": 3e-4}
    if ref_tol is not None:
        ref["ref_tol"] = ref_tol
    run = {"tolerance": 3e-3, "error": 1.5e-3, "estimate": 2.5e-3, "degree": 2, "order": 2, "k": 0.1, "cells": 100,
           "dofs": 500, "planning_seconds": 0.5, "loop_seconds": 0.1, "cost": 0.6, "failure": None,
           "uniform_best": None}
    return {"reference": ref, "runs": [] if failure else [run], "uniform": []}


def test_a_kept_scene_must_have_the_reference_tolerance_asked_of_it():
    earlier = {"tolerances": [1e-2, 3e-3], "ref_tol": 1e-4,
               "scenes": {"example1": _scene(1e-4), "hard": _scene(1e-3), "example2": _scene(),  # no key: the global
                          "example3": _scene(1e-4, failure=True)}}
    scenes = ["example1", "hard", "example2", "example3"]
    assert set(_kept(earlier, [1e-2, 3e-3], 1e-4, {"hard": 1e-3}, scenes)) == {"example1", "hard", "example2"}
    assert set(_kept(earlier, [1e-2, 3e-3], 1e-4, {}, scenes)) == {"example1", "example2"}  # hard was at 1e-3
    assert set(_kept(earlier, [1e-2, 3e-3], 1e-4, {"hard": 1e-3}, ["hard"])) == {"hard"}
    assert _kept(earlier, [1e-2], 1e-4, {"hard": 1e-3}, scenes) == {}  # other tolerances: nothing is kept


def test_the_output_states_a_scenes_own_reference_tolerance(tmp_path):
    result = {"tolerances": [3e-3], "ref_tol": 1e-4,
              "scenes": {"example1": _scene(1e-4), "hard": _scene(1e-3), "example1-gap0.02": _scene(2e-4, failure=True)}}
    _write(result, tmp_path)
    md = (tmp_path / "tolerance.md").read_text()
    ref_rows = [line for line in md.splitlines() if line.startswith("| hard | 0.001")]
    assert ref_rows and "(this scene's own)" in ref_rows[0], md
    assert any(line.startswith("| example1 | 0.0001 |") and "own" not in line for line in md.splitlines()), md
    assert "reference's own error / TOL" in md
    run_row = next(line for line in md.splitlines() if line.startswith("| hard | 0.003 |"))
    assert "| 0.10 |" in run_row, run_row  # its reference's own error 3e-4 over TOL 3e-3
    assert "example1-gap0.02: no reference at 0.0002: out of reach" in md
    rows = (tmp_path / "tolerance.csv").read_text().splitlines()
    assert "ref_tol" in rows[0].split(",") and "ref_error_over_tol" in rows[0].split(",")
    back = json.loads((tmp_path / "tolerance.json").read_text())
    assert back["scenes"]["hard"]["reference"]["ref_tol"] == 1e-3


def test_the_output_gives_the_cost_ratio_with_and_without_planning(tmp_path):
    """cost / uniform counts planning and loop, loop / uniform the loop alone; each has its count below the table."""
    scene = _scene(1e-4)
    scene["runs"][0]["uniform_best"] = {"degree": 2, "order": 1, "mesh": "n=8", "k": 0.1, "error": 2e-3, "cost": 0.2}
    _write({"tolerances": [3e-3], "ref_tol": 1e-4, "scenes": {"example1": scene}}, tmp_path)
    md = (tmp_path / "tolerance.md").read_text()
    row = next(line for line in md.splitlines() if line.startswith("| example1 | 0.003 |"))
    assert row.endswith("| 3.00 | 0.50 |"), row  # (0.5 + 0.1) / 0.2 and 0.1 / 0.2
    assert ("Cost within 2x of the cheapest uniform choice: 0 of 1 (planning + loop); the loop alone: 1 of 1 "
            "(0 with no uniform choice") in md
    header = (tmp_path / "tolerance.csv").read_text().splitlines()[0].split(",")
    assert "cost_ratio" in header and "loop_ratio" in header


@pytest.mark.serial
@pytest.mark.parametrize("flag,item,words", [("--scene-ref-tol", "hard=2", "between 0 and 1"),
                                             ("--scene-ref-uniform", "example3=8:20", "rectangle")])
def test_a_bad_scene_reference_is_a_usage_error(tmp_path, flag, item, words):
    out = tmp_path / "o"
    res = subprocess.run(solver_cmd(["study", "tolerance", flag, item, "--output", str(out)]),
                         cwd=ROOT, capture_output=True, text=True)
    assert res.returncode == 2, res.stderr
    assert flag in res.stderr and words in res.stderr and "Traceback" not in res.stderr
    assert not out.exists()


def test_scene_ref_uniform_parses_name_mesh_and_steps():
    assert scene_ref_uniform("hard=128:320") == ("hard", (128, 320))


@pytest.mark.parametrize("item,word", [("hard=128", "even integers"), ("hard=127:320", "even integers"),
                                       ("hard=128:0", "even integers"), ("hard=a:b", "even integers"),
                                       ("nope=8:20", "NAME=N:STEPS"), ("example2=8:20", "rectangle")])
def test_scene_ref_uniform_refuses_bad_items(item, word):
    with pytest.raises(ValueError, match=word):
        scene_ref_uniform(item)


def _uniform_scene():
    sc = _scene()
    sc["reference"]["uniform"] = [128, 320]
    sc["reference"]["estimate"] = None
    return sc


def test_a_kept_scene_must_have_the_uniform_reference_asked_of_it():
    earlier = {"tolerances": [3e-3], "ref_tol": 1e-4, "scenes": {"hard": _uniform_scene(), "example1": _scene(1e-4)}}
    scenes = ["hard", "example1"]
    assert set(_kept(earlier, [3e-3], 1e-4, {}, scenes, {"hard": (128, 320)})) == {"hard", "example1"}
    assert set(_kept(earlier, [3e-3], 1e-4, {}, scenes, {"hard": (64, 320)})) == {"example1"}
    assert set(_kept(earlier, [3e-3], 1e-4, {}, scenes)) == {"example1"}  # asked: a tolerance reference
    assert set(_kept(earlier, [3e-3], 1e-4, {}, scenes, {"example1": (64, 160)})) == set()


def test_the_output_names_a_uniform_reference(tmp_path):
    result = {"tolerances": [3e-3], "ref_tol": 1e-4, "scenes": {"hard": _uniform_scene()}}
    _write(result, tmp_path)
    md = (tmp_path / "tolerance.md").read_text()
    ref_row = next(line for line in md.splitlines() if line.startswith("| hard | uniform"))
    assert "n = 128, k = T/320 (this scene's own)" in ref_row and "| — |" in ref_row, ref_row
    rows = list(csv.DictReader((tmp_path / "tolerance.csv").open()))
    assert rows[0]["ref_tol"] == "" and rows[0]["reference"] == "uniform P2 order 2, n = 128, k = T/320"


def test_replaying_a_kept_run_gives_what_running_it_again_measures():
    """Reference.replay_against (the verified uniform sequence's differences and answer, from the levels kept) equals
    Reference.measure of the same run made again."""
    from studies.tolerance import Reference, scene

    cfg = scene("example1").replace({"time": {"T": 0.2}}, label="test")
    coarse = Reference.uniform(cfg, 4, 4, log=lambda *a: None)
    fine = Reference.uniform(cfg, 8, 8, log=lambda *a: None)
    again = fine.measure(coarse.build())
    assert again["levels"] == 5 and again["error"] > 0
    assert coarse.replay_against(fine) == pytest.approx(again["error"], rel=1e-12)


def test_a_small_cost_ratio_keeps_its_digits(tmp_path):
    """A tolerance run 250x cheaper than its verified uniform alternative reads 0.004, not 0.00 (verified or not)."""
    scene = _scene(1e-4)
    run = scene["runs"][0]  # cost 0.6 s
    run["verified_uniform"] = {"runs": [{"mesh": {"nx": 16, "ny": 16}, "k": 0.01}, {"mesh": {"nx": 32, "ny": 32},
                                        "k": 0.005}], "cost": 150.0, "error": 1e-4, "verified": True}
    unverified = dict(run, tolerance=1e-3, verified_uniform=dict(run["verified_uniform"], cost=300.0, verified=False))
    scene["runs"].append(unverified)
    _write({"tolerances": [3e-3, 1e-3], "ref_tol": 1e-4, "scenes": {"example1": scene}}, tmp_path)
    md = (tmp_path / "tolerance.md").read_text()
    verified = [line for line in md.splitlines() if line.startswith("| example1 |") and "runs" not in line][-2:]
    assert verified[0].endswith("| 150.000 | 0.004 |"), verified[0]
    assert verified[1].endswith("| ≥ 300.000 | ≤ 0.002 |"), verified[1]


def test_the_output_gives_the_levels_judged(tmp_path):
    """Each row says how many levels were compared with the reference (those both runs have), '—' where not kept."""
    scene = _scene(1e-4)
    scene["runs"][0]["levels"] = 3
    _write({"tolerances": [3e-3], "ref_tol": 1e-4, "scenes": {"example1": scene}}, tmp_path)
    md = (tmp_path / "tolerance.md").read_text()
    row = next(line for line in md.splitlines() if line.startswith("| example1 | 0.003 |"))
    assert row.split("|")[5].strip() == "3", row
    assert "Levels judged: the levels a run shares with its reference" in md
