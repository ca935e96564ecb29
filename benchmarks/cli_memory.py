"""The CLI run's peak memory against a plain dolfinx GAMG elasticity solve of the same cube, side by side.

``python benchmarks/cli_memory.py --sizes 32 46 --steps 4`` runs, for each size and in each round, one after the
other and each in its own process:

- ``plain``: ``python -m studies.anchor N gamg`` (the plain-elasticity yardstick, studies/anchor.py);
- ``cli``: ``python -m solver run configs/example1_3d.toml`` on the n x n x n box, iterative solver, ``--steps``
  steps of k = 0.02, its default outputs (solution.xdmf, contact.xdmf, timeseries.csv, contact.csv, config.toml)
  and a checkpoint every ``--checkpoint-every`` levels (default 2: the run writes one before it ends; a default run
  of 4 steps writes none, its first comes at level 100);
- ``cli-noxdmf`` (with ``--no-xdmf``): the same with ``output.xdmf = false``.

The peak is the process's largest resident set (``ru_maxrss`` of ``os.wait4``), the same measure as the anchor's
``getrusage``; the resident set is also sampled every 20 ms (``/proc/PID/status`` VmRSS) to say when the peak
came. The step is the mean wall time of the CLI's steps after level 0 (timeseries.csv, output included) over one
plain GAMG solve (the anchor's median). Results: ``OUT/cli_memory.json`` and ``OUT/cli_memory.md``
(default OUT: benchmarks/results). One process (no mpirun); run nothing else heavy beside it.
"""

from __future__ import annotations

import argparse
import csv
import json
import os
import shutil
import statistics
import subprocess
import sys
import tempfile
import threading
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
SCENE = ROOT / "configs" / "example1_3d.toml"
K = 0.02


def _rss_mib(pid: int) -> float | None:
    try:
        with open(f"/proc/{pid}/status") as f:
            for line in f:
                if line.startswith("VmRSS:"):
                    return int(line.split()[1]) / 1024.0
    except OSError:
        return None
    return None


def spawn(cmd: list[str], cwd: Path) -> dict:
    """Run ``cmd``; its peak resident set (wait4), the sampled resident set and its output."""
    env = dict(os.environ, OMP_NUM_THREADS="1")
    out, err = tempfile.TemporaryFile(), tempfile.TemporaryFile()
    t0 = time.perf_counter()
    proc = subprocess.Popen(cmd, cwd=cwd, env=env, stdout=out, stderr=err)
    samples: list[tuple[float, float]] = []
    done = threading.Event()

    def sample() -> None:
        while not done.is_set():
            rss = _rss_mib(proc.pid)
            if rss is not None:
                samples.append((time.perf_counter() - t0, rss))
            done.wait(0.02)

    sampler = threading.Thread(target=sample, daemon=True)
    sampler.start()
    _, status, usage = os.wait4(proc.pid, 0)
    proc.returncode = os.waitstatus_to_exitcode(status)
    done.set()
    sampler.join()
    out.seek(0)
    err.seek(0)
    stdout, stderr = out.read().decode(), err.read().decode()
    if proc.returncode != 0:
        raise RuntimeError(f"{' '.join(cmd)}: exit code {proc.returncode}: {stderr[-600:]}")
    peak_at = max(samples, key=lambda s: s[1]) if samples else (float("nan"), float("nan"))
    return {"peak_mib": usage.ru_maxrss / 1024.0, "wall_s": time.perf_counter() - t0, "stdout": stdout,
            "sampled_peak_mib": peak_at[1], "sampled_peak_at_s": peak_at[0],
            "samples": [(round(t, 2), round(r, 1)) for t, r in samples[:: max(1, len(samples) // 300)]]}


def plain(n: int) -> dict:
    res = spawn([sys.executable, "-m", "studies.anchor", str(n), "gamg"], ROOT)
    case = json.loads(res["stdout"].strip().splitlines()[-1])
    return {"peak_mib": res["peak_mib"], "solve_s": case["solve_s"], "dofs": case["dofs"],
            "iterations": case["iterations"], "wall_s": res["wall_s"], "samples": res["samples"]}


def cli(n: int, steps: int, xdmf: bool, checkpoint_every: int, tmp: Path) -> dict:
    out = tmp / f"run_{n}_{int(xdmf)}"
    sets = [f"mesh.nx={n}", f"mesh.ny={n}", f"mesh.nz={n}", f"time.k={K}", f"time.T={K * steps}",
            "solver.linear='iterative'", f"output.checkpoint_every={checkpoint_every}"]
    if not xdmf:
        sets.append("output.xdmf=false")
    cmd = [sys.executable, "-m", "solver", "run", str(SCENE), "--output", str(out), "--overwrite", "--no-progress",
           *(a for s in sets for a in ("--set", s))]
    res = spawn(cmd, ROOT)
    with open(out / "timeseries.csv") as f:
        rows = list(csv.DictReader(f))
    steady = rows[1:]
    disk = sum(p.stat().st_size for p in out.rglob("*") if p.is_file())
    shutil.rmtree(out)
    return {"peak_mib": res["peak_mib"], "wall_s": res["wall_s"],
            "step_s": statistics.mean(float(r["wall_time"]) for r in steady),
            "output_s": statistics.mean(float(r["time_output"]) for r in steady),
            "level0_s": float(rows[0]["wall_time"]), "contact_force": float(rows[-1]["contact_force"]),
            "checkpoint": (out / "checkpoint.h5").name if checkpoint_every else None, "disk_bytes": disk,
            "sampled_peak_at_s": res["sampled_peak_at_s"], "samples": res["samples"],
            "command": "python -m solver run configs/example1_3d.toml " + " ".join(f"--set {s}" for s in sets)}


def report(results: dict) -> str:
    a = results["args"]
    lines = ["# The CLI run's peak memory against a plain GAMG solve of the same cube", "",
             f"Command: `python benchmarks/cli_memory.py --sizes {' '.join(map(str, a['sizes']))} --steps {a['steps']} "
             f"--rounds {a['rounds']} --checkpoint-every {a['checkpoint_every']}"
             f"{' --no-xdmf' if a['no_xdmf'] else ''}` ({results['date']}, commit {results['commit']}, "
             f"load average {results['load']}).", "",
             "Each case in its own process, one after the other in each round; peak = the process's largest resident "
             "set (wait4's ru_maxrss). `cli`: `solver run configs/example1_3d.toml`, iterative solver, "
             f"{a['steps']} steps of k = {K}, default outputs and a checkpoint every {a['checkpoint_every']} levels. "
             "Step = the CLI's mean step (output included) over one plain GAMG solve. Several rounds: median "
             "[min, max].", "",
             "| n | dofs | case | peak MiB | peak / plain | B/dof | step / plain solve | output per step (ms) |",
             "|---|---|---|---|---|---|---|---|"]

    def fmt(xs: list[float], f: str) -> str:
        m = statistics.median(xs)
        return format(m, f) if len(xs) == 1 else f"{format(m, f)} [{format(min(xs), f)}, {format(max(xs), f)}]"

    for n, by in results["cases"].items():
        p = by["plain"]
        dofs = p[0]["dofs"]
        lines.append(f"| {n} | {dofs:,} | plain GAMG | {fmt([c['peak_mib'] for c in p], ',.0f')} | 1 "
                     f"| {fmt([c['peak_mib'] * 2 ** 20 / dofs for c in p], ',.0f')} | 1 | - |")
        for name in ("cli", "cli-noxdmf"):
            cs = by.get(name)
            if not cs:
                continue
            ratio = [c["peak_mib"] / q["peak_mib"] for c, q in zip(cs, p)]
            step = [c["step_s"] / q["solve_s"] for c, q in zip(cs, p)]
            lines.append(f"| {n} | {dofs:,} | {name} | {fmt([c['peak_mib'] for c in cs], ',.0f')} "
                         f"| {fmt(ratio, '.2f')} | {fmt([c['peak_mib'] * 2 ** 20 / dofs for c in cs], ',.0f')} "
                         f"| {fmt(step, '.2f')} | {fmt([1e3 * c['output_s'] for c in cs], ',.0f')} |")
    return "\n".join(lines) + "\n"


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(prog="python benchmarks/cli_memory.py", description=__doc__.splitlines()[0])
    p.add_argument("--sizes", type=int, nargs="+", default=[32, 46], help="box sizes n (3 (n+1)^3 dofs)")
    p.add_argument("--steps", type=int, default=4)
    p.add_argument("--rounds", type=int, default=1)
    p.add_argument("--checkpoint-every", type=int, default=2)
    p.add_argument("--no-xdmf", action="store_true", help="also run the CLI with output.xdmf = false")
    p.add_argument("--out", default=str(ROOT / "benchmarks" / "results"))
    p.add_argument("--name", default="cli_memory", help="file names OUT/NAME.json and .md")
    a = p.parse_args(argv)
    commit = subprocess.run(["git", "rev-parse", "--short", "HEAD"], cwd=ROOT, capture_output=True,
                            text=True).stdout.strip()
    results = {"args": vars(a), "date": time.strftime("%Y-%m-%d %H:%M UTC", time.gmtime()), "commit": commit,
               "load": " ".join(f"{x:.1f}" for x in os.getloadavg()), "cases": {}}
    with tempfile.TemporaryDirectory(dir=ROOT / "benchmarks") as tmp:
        for n in a.sizes:
            by = results["cases"].setdefault(str(n), {"plain": [], "cli": [], "cli-noxdmf": []})
            for r in range(a.rounds):
                by["plain"].append(plain(n))
                by["cli"].append(cli(n, a.steps, True, a.checkpoint_every, Path(tmp)))
                if a.no_xdmf:
                    by["cli-noxdmf"].append(cli(n, a.steps, False, a.checkpoint_every, Path(tmp)))
                print(f"n = {n} round {r + 1}: plain {by['plain'][-1]['peak_mib']:.0f} MiB, cli "
                      f"{by['cli'][-1]['peak_mib']:.0f} MiB" + (f", cli-noxdmf {by['cli-noxdmf'][-1]['peak_mib']:.0f} MiB"
                                                             if a.no_xdmf else ""), flush=True)
    out = Path(a.out)
    out.mkdir(parents=True, exist_ok=True)
    (out / f"{a.name}.json").write_text(json.dumps(results, indent=1) + "\n")
    text = report(results)
    (out / f"{a.name}.md").write_text(text)
    print(text)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
