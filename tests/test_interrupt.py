"""A run stopped by SIGINT/SIGTERM (issue 32, item 3): it ends at the end of the current level with the series,
the CSV and a checkpoint written up to there, says in one line where it stopped and how to continue, exits
128 + the signal, and ``--restart`` then reaches the uninterrupted result (to 1e-12)."""

from __future__ import annotations

import signal
import subprocess
import time
from pathlib import Path

import pytest
from conftest import ROOT, mpi_env, solver_cmd
from conftest import run_cli as cli

from solver.post.compare import UNCOMPARED, compare_runs
from solver.post.results import read_csv, read_results

pytestmark = pytest.mark.serial  # each test starts its own processes

SCENE = ["run", "configs/example1.toml", "--set", "mesh.nx=8", "--set", "mesh.ny=8", "--set", "time.k=0.002",
         "--set", "output.every=3", "--set", "output.checkpoint_every=1000"]


@pytest.fixture(scope="module")
def uninterrupted(tmp_path_factory):
    """A scene run to its end without a stop, once per scene and rank count: the reference that SIGINT's and
    SIGTERM's restarted runs (and the adaptive run's 1 and 2 ranks) are compared with."""
    runs = {}

    def get(scene: list[str], nproc: int) -> Path:
        key = (tuple(scene), nproc)
        if key not in runs:
            out = tmp_path_factory.mktemp(f"ref{nproc}") / "ref"
            res = cli([*scene, "--output", str(out), "--no-progress"], nproc)
            assert res.returncode == 0, res.stderr
            runs[key] = out
        return runs[key]

    return get


def _ranks(mpirun: int) -> list[int]:
    """The processes mpirun started (its children)."""
    kids = []
    for stat in Path("/proc").glob("[0-9]*/stat"):
        try:
            fields = stat.read_text().rsplit(")", 1)[1].split()
        except OSError:
            continue
        if int(fields[1]) == mpirun:
            kids.append(int(stat.parent.name))
    return kids


def _interrupted_run(out: Path, log: Path, nproc: int, signum: int) -> subprocess.CompletedProcess:
    """Start the run, wait for its 20 % progress line, send the signal (to the ranks, as a scheduler does)."""
    cmd = solver_cmd([*SCENE, "--output", str(out)], nproc)
    with open(log, "w") as err:
        proc = subprocess.Popen(cmd, cwd=ROOT, env=mpi_env(), stderr=err, stdout=subprocess.DEVNULL)
        deadline = time.monotonic() + 300
        while " 20% level" not in log.read_text():
            assert proc.poll() is None and time.monotonic() < deadline, log.read_text()
            time.sleep(0.2)
        for pid in ([proc.pid] if nproc == 1 else _ranks(proc.pid)):
            subprocess.run(["kill", f"-{signal.Signals(signum).name}", str(pid)], check=True)
        proc.wait(timeout=300)
    return proc


@pytest.mark.parametrize("nproc", [1, 2])
@pytest.mark.parametrize("signum", [signal.SIGINT, signal.SIGTERM], ids=["SIGINT", "SIGTERM"])
def test_interrupted_run_stops_cleanly_and_restarts_to_the_same_result(tmp_path, uninterrupted, nproc, signum):
    out, log = tmp_path / "o", tmp_path / "log"
    proc = _interrupted_run(out, log, nproc, signum)
    text = log.read_text()
    assert "Traceback" not in text and "KeyboardInterrupt" not in text, text
    stopped = [ln for ln in text.splitlines() if ln.startswith("stopped by")]
    assert len(stopped) == 1 and f"stopped by {signal.Signals(signum).name} at the end of step " in stopped[0], text
    assert "--restart" in stopped[0] and str(out) in stopped[0]
    step = int(stopped[0].split("step ")[1].split(" ")[0])
    if nproc == 1:
        assert proc.returncode == 128 + signum
    else:
        assert proc.returncode != 0  # mpirun reports the ranks' 128 + signum as its own failure
    import h5py

    with h5py.File(out / "checkpoint.h5") as h5:
        assert int(h5.attrs["step"]) == step
    rows = read_csv(out / "timeseries.csv")
    assert [int(r["step"]) for r in rows] == list(range(step + 1))
    got = read_results(out)
    assert got["times"][-1] == pytest.approx(0.002 * (step - step % 3))
    # continue, and compare with a run that was not stopped
    restart = cli([*SCENE, "--output", str(out), "--restart", "--no-progress"], nproc)
    assert restart.returncode == 0, restart.stderr
    _same(out, uninterrupted(SCENE, nproc))


def _same(a: Path, b: Path) -> None:
    diff = compare_runs(a, b)
    assert diff.levels == 501 and diff.same, diff.differences[:5]


ADAPTIVE = ["run", "configs/example1.toml", "--set", "mesh.nx=8", "--set", "mesh.ny=8", "--set", "time.k=0.001",
            "--set", "time.adaptive=true", "--set", "time.tolerance=1e-3", "--set", "output.every=25",
            "--set", "output.checkpoint_every=20", "--no-progress"]


def _rows(path: Path) -> list[dict]:
    return read_csv(path / "timeseries.csv") if (path / "timeseries.csv").exists() else []


def _same_adaptive(a: Path, b: Path) -> None:
    """The same levels (their times and steps, estimates, rejections and results) to 1e-12."""
    ra, rb = _rows(a), _rows(b)
    assert len(ra) == len(rb) and len(ra) > 100
    for x, y in zip(ra, rb):
        for c in x:
            if c.startswith("time_") or c in UNCOMPARED:
                continue
            assert float(x[c]) == pytest.approx(float(y[c]), rel=1e-12, abs=1e-12), (x["step"], c, x[c], y[c])


@pytest.mark.parametrize("nproc", [1, 2])
def test_sigkill_during_an_adaptive_run_and_restart_equals_the_uninterrupted_run(tmp_path, uninterrupted, nproc):
    """The checkpoint carries the step history, the controller's memory and the extrapolation's past levels:
    the restarted run takes the same steps as the uninterrupted one (and 2 ranks the same as 1)."""
    out, log = tmp_path / "o", tmp_path / "log"
    ref = uninterrupted(ADAPTIVE, nproc)
    with open(log, "w") as err:
        proc = subprocess.Popen(solver_cmd([*ADAPTIVE, "--output", str(out)], nproc), cwd=ROOT, env=mpi_env(),
                                stderr=err, stdout=subprocess.DEVNULL)
        deadline = time.monotonic() + 300
        csv = out / "timeseries.csv"
        while not csv.exists() or csv.read_text().count("\n") < 120:  # complete rows, read while written
            assert proc.poll() is None and time.monotonic() < deadline, log.read_text()
            time.sleep(0.05)
        for pid in ([proc.pid] if nproc == 1 else _ranks(proc.pid)):
            subprocess.run(["kill", "-KILL", str(pid)], check=True)
        proc.wait(timeout=300)
    killed_at = len(_rows(out))
    restart = cli([*ADAPTIVE, "--output", str(out), "--restart"], nproc)
    assert restart.returncode == 0, restart.stderr
    assert killed_at < len(_rows(ref))  # it was stopped before the end
    _same_adaptive(out, ref)
    if nproc == 2:  # the one-process reference (the nproc = 1 case's, when it ran first)
        _same_adaptive(uninterrupted(ADAPTIVE, 1), ref)
