"""What writing every level costs the whole command: Example 1 (n = 32, k = 0.001: 1,001 levels) run with
``output.every = 1`` against ``output.every = 0`` (no fields, no contact profile), in this tree and optionally in
another (``--base``), alternated: (base every=1, base every=0, this every=1, this every=0) for ``--rounds`` rounds.

Reports, per tree, the median and range of the ratio every=1 / every=0 of the same round, in wall time and in CPU
time (user + system of the child process: steadier than wall time on a loaded machine, where waiting for a core
counts in the wall time), and the medians of the time loop's output time (the time series' ``time_output``).
Writes ``NAME.json`` and ``NAME.md`` to ``--output``.

    python scripts/output_speed.py --base /work/main --rounds 5
"""

from __future__ import annotations

import argparse
import csv
import json
import os
import resource
import shlex
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]


def _cpu() -> float:
    """User + system seconds of the finished child processes so far."""
    r = resource.getrusage(resource.RUSAGE_CHILDREN)
    return r.ru_utime + r.ru_stime


def _once(src: Path, every: int, sets: list[str], out: Path) -> tuple[float, float, float]:
    """(whole command, output time in the loop, the command's CPU time) seconds of one run of ``src``'s CLI."""
    cmd = [sys.executable, "-m", "solver", "run", str(src / "configs" / "example1.toml"), "--output", str(out),
           "--overwrite", "--no-progress", "--set", f"output.every={every}", *(a for s in sets for a in ("--set", s))]
    t0, c0 = time.perf_counter(), _cpu()
    subprocess.run(cmd, env={**os.environ, "PYTHONPATH": str(src)}, cwd=src, check=True, capture_output=True)
    whole, cpu = time.perf_counter() - t0, _cpu() - c0
    with (out / "timeseries.csv").open() as f:
        output = sum(float(r["time_output"]) for r in csv.DictReader(f))
    return whole, output, cpu


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--base", type=Path, default=None, help="a checkout of other code, measured alternately")
    ap.add_argument("--rounds", type=int, default=5)
    ap.add_argument("--n", type=int, default=32)
    ap.add_argument("--k", type=float, default=0.001)
    ap.add_argument("--name", default="output_speed")
    ap.add_argument("--output", type=Path, default=ROOT / "benchmarks" / "results")
    args = ap.parse_args(argv)
    sets = [f"mesh.nx={args.n}", f"mesh.ny={args.n}", f"time.k={args.k}"]
    trees = ({"base": args.base.resolve()} if args.base else {}) | {"this": ROOT}
    runs: dict[str, dict[int, list[tuple[float, float]]]] = {name: {1: [], 0: []} for name in trees}
    with tempfile.TemporaryDirectory() as tmp:
        for src in trees.values():  # the form cache warm
            _once(src, 0, sets, Path(tmp) / "warm")
        for r in range(args.rounds):
            for name, src in trees.items():
                for every in (1, 0):
                    runs[name][every].append(_once(src, every, sets, Path(tmp) / f"{name}{every}"))
            print(f"round {r + 1}: " + ", ".join(
                f"{name} {runs[name][1][-1][0] / runs[name][0][-1][0]:.3f} (cpu "
                f"{runs[name][1][-1][2] / runs[name][0][-1][2]:.3f})" for name in trees), flush=True)
    rows = {}
    for name in trees:
        pairs = [a[0] / b[0] for a, b in zip(runs[name][1], runs[name][0], strict=True)]
        cpu = [a[2] / b[2] for a, b in zip(runs[name][1], runs[name][0], strict=True)]
        rows[name] = {"ratio_median": statistics.median(pairs), "ratio_min": min(pairs), "ratio_max": max(pairs),
                      "cpu_ratio_median": statistics.median(cpu), "cpu_ratio_min": min(cpu), "cpu_ratio_max": max(cpu),
                      "load_average": os.getloadavg(),
                      "every1_median_s": statistics.median(a[0] for a in runs[name][1]),
                      "every0_median_s": statistics.median(a[0] for a in runs[name][0]),
                      "output_median_s": statistics.median(a[1] for a in runs[name][1]), "runs": runs[name]}
    args.output.mkdir(parents=True, exist_ok=True)
    (args.output / f"{args.name}.json").write_text(json.dumps({"n": args.n, "k": args.k, "rounds": args.rounds,
                                                              "base": str(args.base), "trees": rows}, indent=1))
    lines = [f"# Writing every level: Example 1, n = {args.n}, k = {args.k} ({round(1 / args.k) + 1} levels)", "",
             "`python scripts/output_speed.py " + shlex.join(argv if argv is not None else sys.argv[1:]) + "`", "",
             f"{args.rounds} alternated rounds; the ratio is each round's whole `solver run` with `output.every = 1` "
             "over the same tree's run with `output.every = 0`, in wall time and in CPU time (user + system of the "
             f"command). Load average at the end: {' '.join(f'{x:.1f}' for x in os.getloadavg())} (2 cores).", "",
             "| tree | every=1 / every=0, wall (min–max) | CPU (min–max) | every=1, every=0 wall medians (s) | "
             "output time in the loop (s) |",
             "|---|---|---|---|---|"]
    for name, row in rows.items():
        label = f"{name} ({trees[name]})"
        lines.append(f"| {label} | {row['ratio_median']:.3f} ({row['ratio_min']:.2f}–{row['ratio_max']:.2f}) | "
                     f"{row['cpu_ratio_median']:.3f} ({row['cpu_ratio_min']:.2f}–{row['cpu_ratio_max']:.2f}) | "
                     f"{row['every1_median_s']:.2f}, {row['every0_median_s']:.2f} | {row['output_median_s']:.2f} |")
    (args.output / f"{args.name}.md").write_text("\n".join(lines) + "\n")
    print("\n".join(lines[-len(rows):]))
    return 0


if __name__ == "__main__":
    sys.exit(main())
