"""solver.io.launch: what a run records about where it wrote."""

import tomllib

from solver import api
from solver.config import from_dict
from solver.io.launch import directed

SCENE = {"mesh": {"nx": 4, "ny": 4}, "time": {"T": 0.2, "k": 0.1}, "output": {"directory": "results/elsewhere"}}


def test_the_resolved_scene_names_the_directory_the_run_wrote(comm, shared_tmp):
    out = shared_tmp / "given"
    api.run(from_dict(SCENE), output=out, comm=comm)
    resolved = tomllib.loads((out / "config.toml").read_text())
    assert resolved["output"]["directory"] == str(out)


def test_directed_changes_only_the_directory():
    cfg = from_dict(SCENE)
    moved = directed(cfg, "runs/a")
    assert moved.output.directory == "runs/a" and moved.document["output"]["directory"] == "runs/a"
    assert cfg.output.directory == "results/elsewhere" and cfg.document["output"]["directory"] == "results/elsewhere"
    assert moved.replace({}).output.directory == "runs/a"  # a later change keeps it
    assert directed(moved, "runs/a") is moved
