"""The Python interface (solver/api.py): the same results as the CLI, the same one-line errors, no strings."""

import json

import numpy as np
import pytest
from conftest import ROOT, run_cli

from solver import api
from solver.errors import ConfigError, OutputDirectoryError, UsageError
from solver.post.results import read_csv, read_results

EXAMPLE1 = ROOT / "configs" / "example1.toml"


def _csv_columns(rows):
    return [c for c in rows[0] if not c.startswith("time_") and c != "wall_time"]


def _rel(a, b) -> float:
    a, b = np.asarray(a, float), np.asarray(b, float)
    return float(np.max(np.abs(a - b)) / max(np.max(np.abs(a)), np.max(np.abs(b)), 1e-300))


@pytest.mark.serial
def test_api_reproduces_cli_example1(tmp_path):
    """`python -m solver run configs/example1.toml` and api.run(api.load(...)) agree to 1e-12 in every CSV column
    and every field at every written level; the in-memory run's series and final fields agree with the files."""
    cli = tmp_path / "cli"
    res = run_cli(["run", str(EXAMPLE1), "--no-progress", "--output", str(cli)])
    assert res.returncode == 0, res.stderr
    out = api.run(api.load(EXAMPLE1), tmp_path / "api")
    a, b = read_csv(cli / "timeseries.csv"), read_csv(tmp_path / "api" / "timeseries.csv")
    assert len(a) == len(b) == 101
    for c in _csv_columns(a):
        assert _rel([r[c] for r in a], [r[c] for r in b]) <= 1e-12, c
        assert _rel([r[c] for r in a], out.series[c]) <= 1e-12, c
    fa, fb = read_results(cli)["fields"], read_results(tmp_path / "api")["fields"]
    assert fa.keys() == fb.keys() and len(fa["displacement"]) == 101
    for name in fa:
        assert fa[name].keys() == fb[name].keys()
        for t in fa[name]:
            assert _rel(fa[name][t], fb[name][t]) <= 1e-12, (name, t)
    last = read_results(cli)
    assert _rel(last["fields"]["displacement"][1.0][:, :2], out.fields["displacement"]) <= 1e-12
    assert _rel(last["fields"]["damage"][1.0].ravel(), out.fields["damage"]) <= 1e-12
    assert np.array_equal(last["geometry"], out.points)


SMALL = {"mesh": {"nx": 4, "ny": 4}, "time": {"k": 0.25},
         "boundary": {"left": {"role": "clamped"}, "right": {"role": "traction", "traction": [-10.0, -10.0]},
                      "bottom": {"role": "contact", "gap": 0.0, "mu": 1e-10}}}


def test_in_memory_equals_files(comm, shared_tmp):
    """A run in memory and the same run written and read back (api.read) give the same series and final fields,
    on every rank (the fields gathered in input order)."""
    cfg = api.scene(SMALL)
    mem = api.run(cfg)
    assert mem.directory is None and mem.model is not None
    disk = api.run(cfg, shared_tmp / "r")
    back = api.read(shared_tmp / "r")
    assert back.columns == disk.columns == mem.columns
    assert len(mem.series["t"]) == 5 and mem.table("t", "zeta_min").shape == (5, 2)
    for c in mem.columns:
        if not c.startswith("time_") and c != "wall_time":
            assert np.array_equal(mem.series[c], disk.series[c]), c
            assert _rel(mem.series[c], back.series[c]) <= 1e-12, c
    for name in ("displacement", "damage"):
        assert np.array_equal(mem.fields[name], disk.fields[name])
        assert _rel(mem.fields[name], back.fields[name]) <= 1e-12, name
    assert np.array_equal(mem.points, back.points)
    # the contact profile of every written level, in memory as in contact.csv (read back by read_contact)
    assert mem.contact.keys() == back.contact.keys() == {"bottom"}
    c, b = mem.contact["bottom"], back.contact["bottom"]
    assert c["pressure"].shape == (5, 5) and np.array_equal(c["step"], [0, 1, 2, 3, 4])
    assert np.array_equal(c["t"], back.series["t"]) and c.keys() == b.keys()
    for k in c:
        assert _rel(c[k], b[k]) <= 1e-12, k
    assert np.array_equal(api.read_contact(shared_tmp / "r")["bottom"]["pressure"], b["pressure"])


SWEEP = """
import sys
from solver import api
from solver.run import formcache
done = {"n": 0}
compile_ = formcache._compile
def counted(*a, **k):
    done["n"] += 1
    return compile_(*a, **k)
formcache._compile = counted
cfg = api.scene(%r)
for mu in (1e-8, 2e-8, 4e-8):
    res = api.run(cfg.replace({"boundary": {"bottom": {"mu": mu}}}))
    print(mu, done["n"], res.series["contact_force"][-1], flush=True)
"""


@pytest.mark.serial
@pytest.mark.slow
def test_a_compliance_sweep_compiles_its_forms_once_and_says_nothing(tmp_path):
    """Three compliances from Python in a fresh FFCx cache: the first run compiles every form, the next two none
    (the compliance is a fem.Constant, not a number in the C code); stderr stays empty although the first compiled."""
    import os
    import subprocess
    import sys

    env = dict(os.environ, XDG_CACHE_HOME=str(tmp_path / "cache"))
    res = subprocess.run([sys.executable, "-c", SWEEP % (SMALL,)], cwd=ROOT, env=env, capture_output=True, text=True,
                         timeout=900)
    assert res.returncode == 0, res.stderr[-3000:]
    counts = [int(line.split()[1]) for line in res.stdout.splitlines()]
    assert len(counts) == 3 and counts[0] > 0 and counts[2] == counts[0], res.stdout
    forces = [float(line.split()[2]) for line in res.stdout.splitlines()]
    assert len(set(forces)) == 3  # the compliance did change the runs
    assert res.stderr == ""


def test_study_in_a_loop_without_strings(comm):
    """replace() in a loop: a larger traction gives a larger contact force (and a run per value)."""
    base = api.scene(SMALL)
    forces = []
    for f in (-5.0, -10.0):
        cfg = base.replace({"boundary": {"right": {"role": "traction", "traction": [f, f]}}})
        forces.append(api.run(cfg).series["contact_force"][-1])
    assert forces[1] > forces[0] > 0


def test_errors_are_the_scene_files(comm, shared_tmp):
    """A bad change is the one-line ConfigError a file gives; earlier results are not overwritten silently."""
    with pytest.raises(ConfigError) as exc:
        api.scene(SMALL).replace({"time": {"k": -1.0}})
    assert exc.value.key == "time.k" and "\n" not in str(exc.value)
    with pytest.raises(ConfigError) as exc:
        api.scene({"mesh": {"nx": "many"}})
    assert exc.value.key == "mesh.nx"
    cfg = api.scene(SMALL)
    api.run(cfg, shared_tmp / "once")
    with pytest.raises(UsageError, match="overwrite=True"):
        api.run(cfg, shared_tmp / "once")
    api.run(cfg, shared_tmp / "once", overwrite=True)
    with pytest.raises(ConfigError) as exc:
        api.run(cfg, tolerance=2.0)
    assert exc.value.key == "accuracy.tolerance"


def test_earlier_results_are_a_typed_refusal_and_overwrite_leaves_no_stale_profile(comm, shared_tmp):
    """overwrite=True removes every file a run writes: a scene without contact leaves no contact.csv of the one
    before (which `solver plot` would draw)."""
    out = shared_tmp / "r"
    api.run(api.scene(SMALL), out)
    comm.barrier()
    assert (out / "contact.csv").is_file()
    free = api.scene({**SMALL, "boundary": {**SMALL["boundary"], "bottom": {"role": "traction", "traction": [0.0, 0.0]}}})
    with pytest.raises(OutputDirectoryError) as exc:
        api.run(free, out)
    assert exc.value.problem == "earlier results" and "contact.csv" in exc.value.existing
    assert isinstance(exc.value, UsageError)
    api.run(free, out, overwrite=True)
    comm.barrier()
    assert (out / "timeseries.csv").is_file() and not (out / "contact.csv").exists()


def _close(a, b) -> bool:
    """The same JSON document, numbers to 1e-12 relative."""
    if isinstance(a, dict) and isinstance(b, dict):
        return a.keys() == b.keys() and all(_close(a[k], b[k]) for k in a)
    if isinstance(a, list) and isinstance(b, list):
        return len(a) == len(b) and all(_close(x, y) for x, y in zip(a, b))
    if isinstance(a, float) or isinstance(b, float):
        return a == pytest.approx(b, rel=1e-12, abs=0)
    return a == b


TOLERANCE = ["--tolerance", "1e-2", "--set", "time.T=0.2"]


@pytest.mark.serial
def test_tolerance_runs_as_the_cli_does(tmp_path):
    """api.run(cfg, dir, tolerance=...) makes the plan `solver run --tolerance` makes and the same results: plan.json,
    the chosen mesh, every CSV column (the error estimates too) and the fields."""
    cli = tmp_path / "cli"
    res = run_cli(["run", str(EXAMPLE1), *TOLERANCE, "--no-progress", "--output", str(cli)])
    assert res.returncode == 0, res.stderr
    out = api.run(api.load(EXAMPLE1).replace({"time": {"T": 0.2}}), tmp_path / "api", tolerance=1e-2)
    want, got = (json.loads((d / "plan.json").read_text()) for d in (cli, tmp_path / "api"))
    for d in (want, got):  # seconds
        d.pop("planning_seconds"), d.pop("planning_stages")
        for r in d["adaptation"]:
            r.pop("seconds", None)
    assert _close(got, want), (got, want)
    assert set(want["ingredients"]) >= {"memory", "damage", "truncation", "order"}  # each ingredient's change
    for name in want["ingredients"]:  # and one line each at the end of the run
        assert f"{name}: changes the answer by" in res.stdout + res.stderr
    assert out.plan.degree == want["u_degree"] and out.plan.k == want["k"]
    assert (tmp_path / "api" / "mesh.xdmf").read_text() == (cli / "mesh.xdmf").read_text()
    a, b = read_csv(cli / "timeseries.csv"), read_csv(tmp_path / "api" / "timeseries.csv")
    assert list(a[0]) == list(b[0]) == list(out.columns) and "est_space" in out.columns
    for c in _csv_columns(a):
        assert _rel([r[c] for r in a], [r[c] for r in b]) <= 1e-12, c
        assert _rel([r[c] for r in a], out.series[c]) <= 1e-12, c
    fa, fb = read_results(cli)["fields"], read_results(tmp_path / "api")["fields"]
    for name in fa:
        for t in fa[name]:
            assert _rel(fa[name][t], fb[name][t]) <= 1e-12, (name, t)
