"""The command line as a user meets it: exit codes, one-line errors, no silent overwrite, MPI."""

import os
import subprocess
import sys

import pytest
from conftest import ROOT

pytestmark = pytest.mark.serial  # each test starts its own processes


def cli(args, nproc=1):
    env = dict(os.environ, OMPI_ALLOW_RUN_AS_ROOT="1", OMPI_ALLOW_RUN_AS_ROOT_CONFIRM="1")
    cmd = [sys.executable, "-m", "solver", *args]
    if nproc > 1:
        cmd = ["mpirun", "-n", str(nproc), "--oversubscribe", *cmd]
    return subprocess.run(cmd, cwd=ROOT, env=env, capture_output=True, text=True, timeout=300)


SMALL = ["--set", "mesh.nx=4", "--set", "mesh.ny=4", "--set", "time.k=0.5", "--no-progress"]


@pytest.mark.parametrize("nproc", [1, 2])
def test_bad_value_is_one_line_exit_2(tmp_path, nproc):
    out = tmp_path / "o"
    res = cli(["run", "configs/example1.toml", "--set", "material.E=-3", "--output", str(out)], nproc)
    assert res.returncode == 2
    # exactly one message (rank 0), whatever mpirun itself adds about the exit code
    ours = [ln for ln in res.stderr.splitlines() if ln.startswith(("error", "failed", "scene"))]
    assert ours == ["error: configs/example1.toml: material.E = -3.0: must be > 0"], res.stderr
    if nproc == 1:
        assert res.stderr.strip() == ours[0]
    assert "Traceback" not in res.stderr and not out.exists()


def test_incompatible_interval_refused_before_output(tmp_path):
    out = tmp_path / "o"
    res = cli(["run", "configs/example1.toml", "--set", "boundary.bottom.interval=[0.0, 0.3]",
               "--output", str(out), *SMALL])
    assert res.returncode == 2 and "boundary.bottom.interval" in res.stderr and not out.exists()


def test_check_and_no_overwrite(tmp_path):
    res = cli(["check", "configs/example1.toml"])
    assert res.returncode == 0 and "ok" in res.stderr
    out = tmp_path / "o"
    assert cli(["run", "configs/example1.toml", "--output", str(out), *SMALL]).returncode == 0
    before = (out / "timeseries.csv").read_bytes()
    res = cli(["run", "configs/example1.toml", "--output", str(out), *SMALL, "--set", "time.k=0.25"])
    assert res.returncode == 2 and "--overwrite" in res.stderr
    assert (out / "timeseries.csv").read_bytes() == before
    res = cli(["run", "configs/example1.toml", "--output", str(out), *SMALL, "--set", "time.k=0.25", "--overwrite"])
    assert res.returncode == 0 and (out / "timeseries.csv").read_bytes() != before


def test_solver_failure_exits_1_with_reason(tmp_path):
    res = cli(["run", "configs/example1.toml", "--output", str(tmp_path / "o"), *SMALL,
               "--set", "solver.max_it=1"])
    assert res.returncode == 1
    assert "failed: displacement solve at t = 0" in res.stderr and "DIVERGED_MAX_IT" in res.stderr
    assert "Traceback" not in res.stderr
