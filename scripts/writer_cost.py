"""The writer's own cost, in-process: every level of Example 1 written (fields, Γ_C's series, contact.csv, the time
series' row) from one solved state, without the solver, in this tree and in a base tree, alternated.

    python scripts/writer_cost.py [--base /work/main] [--n 128] [--k 0.005] [--rounds 3] [--name writer_cost]

Each run is a new process started in its tree (so that tree's ``solver`` is imported, ``PYTHONPATH`` = the tree):
it builds the model of ``configs/example1.toml`` at ``--n``, ``--k`` (``output.every = 1``), solves levels 0-2, then
times ``solver.io.results._Writers`` writing levels 0 .. steps (a flush every ``output.checkpoint_every`` levels, as
the run does before its checkpoints), from opening the writers to closing them, in CPU time (``process_time``: this
process, its settling thread included) and wall time. The solver's state is the same at every level, so this is what
the writer costs, not what the run's levels cost. Reports per tree the median and range, and the ratio of the medians
and of the adjacent pairs; writes ``NAME.json`` and ``NAME.md`` under ``--out`` (benchmarks/results).
"""

from __future__ import annotations

import argparse
import json
import os
import statistics
import subprocess
import sys
import tempfile
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]

CHILD = r"""
import json, sys, tempfile, time
from pathlib import Path
from mpi4py import MPI
from solver.config.scene import load
from solver.io.launch import launch
import solver.io.results as R
from solver.run.stepper import levels
n, k, out = int(sys.argv[1]), float(sys.argv[2]), Path(sys.argv[3])
cfg = load("configs/example1.toml", [f"mesh.nx={n}", f"mesh.ny={n}", f"time.k={k}", "output.every=1"])
model = launch(cfg, MPI.COMM_WORLD, out, True, False, []).model
gen = levels(model, 0, ())
row = [next(gen) for _ in range(3)][-1]
steps, every = cfg.time.steps, cfg.output.checkpoint_every
c, w = time.process_time(), time.perf_counter()
writers = R._Writers(model, out, (), None, None, None)
for i in range(steps + 1):
    writers.level(dict(row, step=i, t=i * k), i == steps)
    if every and i % every == 0 and 0 < i < steps:
        writers.out.flush()
writers.out.close()
writers.close(True)
print(json.dumps({"cpu": time.process_time() - c, "wall": time.perf_counter() - w, "levels": steps + 1,
                  "solver": __import__("solver").__file__}))
"""


def _once(tree: Path, n: int, k: float, out: Path) -> dict:
    env = {**os.environ, "PYTHONPATH": str(tree)}
    res = subprocess.run([sys.executable, "-c", CHILD, str(n), str(k), str(out)], cwd=tree, env=env, check=True,
                         capture_output=True, text=True)
    rec = json.loads(res.stdout.strip().splitlines()[-1])
    if not rec.pop("solver").startswith(str(tree)):
        raise SystemExit(f"{tree}: imports another tree's solver")
    return rec


def _stats(values: list[float]) -> dict[str, float]:
    return {"median": statistics.median(values), "min": min(values), "max": max(values)}


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--base", type=Path, default=Path("/work/main"))
    ap.add_argument("--n", type=int, default=128)
    ap.add_argument("--k", type=float, default=0.005)
    ap.add_argument("--rounds", type=int, default=3)
    ap.add_argument("--name", default="writer_cost")
    ap.add_argument("--out", type=Path, default=ROOT / "benchmarks" / "results")
    args = ap.parse_args(argv)
    trees = {"base": args.base.resolve(), "this": ROOT}
    runs: dict[str, list[dict]] = {name: [] for name in trees}
    with tempfile.TemporaryDirectory() as tmp:
        for name, tree in trees.items():  # untimed: the form cache and the page cache warm
            _once(tree, args.n, args.k, Path(tmp) / f"warm-{name}")
        for r in range(args.rounds):
            for name, tree in trees.items():
                runs[name].append(_once(tree, args.n, args.k, Path(tmp) / f"{name}{r}"))
                print(name, r, runs[name][-1], os.getloadavg()[0], flush=True)
    stats = {name: {key: _stats([x[key] for x in rs]) for key in ("cpu", "wall")} for name, rs in runs.items()}
    pairs = {key: _stats([a[key] / b[key] for a, b in zip(runs["this"], runs["base"])]) for key in ("cpu", "wall")}
    load = " ".join(f"{x:.1f}" for x in os.getloadavg())
    rev = subprocess.run(["git", "describe", "--always", "--dirty"], cwd=ROOT, capture_output=True, text=True).stdout.strip()
    base_rev = subprocess.run(["git", "describe", "--always", "--dirty"], cwd=trees["base"], capture_output=True,
                              text=True).stdout.strip()
    levels = runs["this"][0]["levels"]
    lines = [f"# The writer alone: Example 1, n = {args.n}, k = {args.k} ({levels} levels written), in-process", "",
             f"`python scripts/writer_cost.py --base {trees['base']} --n {args.n} --k {args.k} --rounds {args.rounds} "
             f"--name {args.name}`: this = {rev}, base = {base_rev}; {args.rounds} rounds alternated (base, this), each "
             f"a new process; the writers open, every level written from one solved state, closed; load average at "
             f"the end {load} (2 cores, shared). Seconds: median [min, max].", "",
             "| | base | this | this / base (medians) | pairs' ratios: median [min, max] |", "|---|---|---|---|---|"]
    for key, label in (("cpu", "CPU (process_time)"), ("wall", "wall")):
        b, a, p = stats["base"][key], stats["this"][key], pairs[key]
        lines.append(f"| {label} | {b['median']:.3f} [{b['min']:.3f}, {b['max']:.3f}] | {a['median']:.3f} "
                     f"[{a['min']:.3f}, {a['max']:.3f}] | {a['median'] / b['median']:.3f} | {p['median']:.3f} "
                     f"[{p['min']:.3f}, {p['max']:.3f}] |")
    lines += ["", f"Per level (CPU, medians): base {1e3 * stats['base']['cpu']['median'] / levels:.2f} ms, this "
              f"{1e3 * stats['this']['cpu']['median'] / levels:.2f} ms.", ""]
    args.out.mkdir(parents=True, exist_ok=True)
    (args.out / f"{args.name}.json").write_text(json.dumps({"args": {k: str(v) for k, v in vars(args).items()},
                                                            "runs": runs, "stats": stats, "pairs": pairs,
                                                            "load": load, "rev": rev, "base_rev": base_rev}, indent=1))
    (args.out / f"{args.name}.md").write_text("\n".join(lines))
    print("\n".join(lines))
    return 0


if __name__ == "__main__":
    sys.exit(main())
