"""A run killed with SIGKILL (at a random moment, or inside a data write of the XDMF series) and restarted
from its checkpoint equals an uninterrupted run."""

import os
import signal
import subprocess
import time

import numpy as np
import pytest
from conftest import ROOT, by_cell, by_node, mpi_env, solver_cmd

from solver.io.timeseries import TIMING_COLUMNS
from solver.post.results import read_csv, read_results

pytestmark = pytest.mark.serial  # starts (and kills) its own processes

SCENE = ["run", "configs/example1.toml", "--no-progress", "--set", "mesh.nx=48", "--set", "mesh.ny=48",
         "--set", "time.k=0.002", "--set", "output.every=25", "--set", "output.checkpoint_every=50",
         "--set", 'output.fields=["displacement", "damage", "stress", "von_mises"]']
STEPS = 500


def _rows(path):
    try:
        return max(0, len(path.read_text().splitlines()) - 1)
    except FileNotFoundError:
        return 0


# the second-order scheme carries more state (u_{n-1}, the previous damage source, the memory's partial sum)
SECOND_ORDER = ["--set", "discretization.u_degree=2", "--set", "time.order=2", "--set", "mesh.nx=24",
                "--set", "mesh.ny=24"]


@pytest.fixture(scope="module")
def uninterrupted(tmp_path_factory):
    """The scene run to its end, once per rank count and scene."""
    runs = {}

    def get(nproc: int, extra: list[str]):
        key = (nproc, tuple(extra))
        if key not in runs:
            out = tmp_path_factory.mktemp(f"full{nproc}") / "full"
            ref = subprocess.run(solver_cmd([*SCENE, *extra, "--output", str(out)], nproc), cwd=ROOT, env=mpi_env(),
                                 capture_output=True, text=True, timeout=600)
            assert ref.returncode == 0, ref.stderr[-3000:]
            runs[key] = out
        return runs[key]

    return get


@pytest.mark.slow
@pytest.mark.parametrize("nproc,kill,extra", [(1, "timed", []), (2, "timed", []), (1, "data", []), (2, "data", []),
                                              (1, "timed", SECOND_ORDER)],
                         ids=["timed", "timed-2ranks", "data", "data-2ranks", "timed-P2-order2"])
def test_kill_and_restart_equals_uninterrupted(tmp_path, uninterrupted, nproc, kill, extra):
    """``timed``: SIGKILL to mpirun and its ranks after about 215 levels. ``data``: the writer SIGKILLs itself
    half-way through the data of the 8th written level (step 175; tests/faults.py): levels 0-150, listed by the
    checkpoint at step 150, stay listed."""
    full, cut = uninterrupted(nproc, extra), tmp_path / "cut"
    scene = [*SCENE, *extra]
    fault = "kill:data:8" if kill == "data" else None
    proc = subprocess.Popen(solver_cmd([*scene, "--output", str(cut)], nproc, fault), cwd=ROOT, env=mpi_env(),
                            stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL, start_new_session=True)
    if kill == "timed":
        deadline = time.time() + 300
        while _rows(cut / "timeseries.csv") < 215 and proc.poll() is None and time.time() < deadline:
            time.sleep(0.002)
        os.killpg(proc.pid, signal.SIGKILL)  # the whole group: mpirun and its ranks
        proc.wait()
        killed_at = _rows(cut / "timeseries.csv")
        assert proc.returncode == -signal.SIGKILL and 200 < killed_at < STEPS + 1, killed_at
        # what the killed run left is readable
        assert read_results(cut)["times"][-1] >= 0.4 - 1e-12
    else:
        proc.wait(timeout=600)
        # one process: killed by the signal; under mpirun: rank 0 was, and mpirun ended the job with an error
        assert proc.returncode == (-signal.SIGKILL if nproc == 1 else proc.returncode) and proc.returncode != 0
        # killed while writing level 175 (in the time loop's thread): its CSV row is not written
        assert _rows(cut / "timeseries.csv") == 175
        left = read_results(cut)
        assert np.allclose(left["times"], [0.05 * i for i in range(7)], rtol=0, atol=1e-12)  # only complete levels
        a = read_results(full)
        for t in left["times"]:  # the same rows in the same order as the uninterrupted run's
            for name in ("displacement", "stress"):
                x, y = left["fields"][name][t], a["fields"][name][t]
                if nproc == 1:  # the same arithmetic
                    assert np.array_equal(x, y), (name, t)
                else:  # two launches partition differently: equal to round-off, as the CSV rows below
                    assert np.allclose(x, y, rtol=1e-10, atol=1e-12), (name, t, np.abs(x - y).max())

    res = subprocess.run(solver_cmd([*scene, "--output", str(cut), "--restart"], nproc), cwd=ROOT, env=mpi_env(),
                         capture_output=True, text=True, timeout=600)
    assert res.returncode == 0, res.stderr[-3000:]

    a, b = read_results(full), read_results(cut)
    assert a["times"] == b["times"]  # no duplicated or missing levels
    T = a["times"][-1]
    for name in ("displacement", "damage"):
        assert np.allclose(by_node(a, name, T), by_node(b, name, T), rtol=0, atol=1e-12), name
    for name in ("stress", "von_mises"):
        assert np.allclose(by_cell(a, name, T), by_cell(b, name, T), rtol=0, atol=1e-12), name
    ra, rb = read_csv(full / "timeseries.csv"), read_csv(cut / "timeseries.csv")
    assert len(ra) == len(rb) == STEPS + 1
    skip = set(TIMING_COLUMNS) | {"factorizations"}  # a restarted process factors its Jacobian once more
    for x, y in zip(ra, rb):
        x, y = ({k: v for k, v in r.items() if k not in skip} for r in (x, y))
        if nproc == 1:  # same partition: the same arithmetic, row for row
            assert x == y
        else:  # parallel launches partition differently: equal to round-off
            assert y == pytest.approx(x, rel=1e-10, abs=1e-12)


@pytest.mark.slow
def test_restart_refuses_another_scene_and_accepts_other_ranks(tmp_path):
    """Checkpoints are keyed by coordinates: a different scene is refused, another rank count continues."""
    out, full = tmp_path / "o", tmp_path / "full"
    args = ["run", "configs/example1.toml", "--no-progress", "--set", "mesh.nx=8", "--set", "mesh.ny=8",
            "--set", "time.k=0.1", "--set", "output.checkpoint_every=4"]
    assert subprocess.run(solver_cmd([*args, "--output", str(full)], 1), cwd=ROOT, env=mpi_env()).returncode == 0
    assert subprocess.run(solver_cmd([*args, "--output", str(out)], 1), cwd=ROOT, env=mpi_env()).returncode == 0
    res = subprocess.run(solver_cmd([*args, "--output", str(out), "--set", "material.E=200", "--restart"], 1), cwd=ROOT,
                         env=mpi_env(), capture_output=True, text=True)
    assert res.returncode == 2 and "the scene differs" in res.stderr
    # continue the finished run's last checkpoint (step 8) on 2 ranks: levels 9 and 10 again
    res = subprocess.run(solver_cmd([*args, "--output", str(out), "--restart"], 2), cwd=ROOT, env=mpi_env(),
                         capture_output=True, text=True)
    assert res.returncode == 0, res.stderr[-2000:]
    a, b = read_results(full), read_results(out)
    assert a["times"] == b["times"]
    assert np.allclose(by_node(a, "displacement", 1.0), by_node(b, "displacement", 1.0), rtol=0, atol=1e-12)
    assert [r["step"] for r in read_csv(out / "timeseries.csv")] == list(range(11))
