"""Is this tree as fast as a base tree? Alternates the two on a few cases and reports the ratios of their medians.

The machine is shared and noisy, so the two trees run in turn (base, this, base, this, ...) and only the ratio of
side-by-side medians is reported: the whole command (start-up, outputs, everything a user waits for) and the
time loop (the sum of the time series' ``wall_time``). Writes ``NAME.json`` and ``NAME.md`` to ``--output``.

    python scripts/same_speed.py --base CHECKOUT_OF_THE_BASE --rounds 5 --name house_speed
"""

from __future__ import annotations

import argparse
import csv
import json
import os
import shlex
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
P2 = ["discretization.u_degree=2", "discretization.zeta_degree=2", "time.order=2"]
CASES: dict[str, tuple[str, list[str]]] = {
    "example1 n=64 P1 k=0.01": ("example1.toml", ["mesh.nx=64", "mesh.ny=64", "time.k=0.01", "output.every=0"]),
    "example1 n=32 P2 order 2 k=0.01": ("example1.toml", ["mesh.nx=32", "mesh.ny=32", "time.k=0.01", *P2,
                                                          "output.every=0"]),
    "hard n=48 P2 order 2 k=0.0125": ("hard.toml", [*P2, "mesh.nx=48", "mesh.ny=48", "time.k=0.0125",
                                                    "output.every=0"]),
    "output: example1 n=32 k=0.001 every level": ("example1.toml", ["mesh.nx=32", "mesh.ny=32", "time.k=0.001",
                                                                   "output.every=1"]),
}


def _once(src: Path, scene: str, sets: list[str], out: Path) -> tuple[float, float]:
    """(whole command, time loop) seconds of one run of ``src``'s CLI."""
    cmd = [sys.executable, "-m", "solver", "run", str(src / "configs" / scene), "--output", str(out), "--overwrite",
           "--no-progress", *(a for s in sets for a in ("--set", s))]
    t0 = time.perf_counter()
    subprocess.run(cmd, env={**os.environ, "PYTHONPATH": str(src)}, cwd=src, check=True, capture_output=True)
    whole = time.perf_counter() - t0
    with (out / "timeseries.csv").open() as f:
        loop = sum(float(r["wall_time"]) for r in csv.DictReader(f))
    return whole, loop


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--base", type=Path, required=True, help="checkout of the base code")
    ap.add_argument("--rounds", type=int, default=5)
    ap.add_argument("--cases", nargs="+", default=list(CASES), choices=list(CASES))
    ap.add_argument("--name", default="same_speed")
    ap.add_argument("--output", type=Path, default=ROOT / "benchmarks" / "results")
    args = ap.parse_args(argv)
    trees = {"base": args.base.resolve(), "this": ROOT}
    results = {}
    with tempfile.TemporaryDirectory() as tmp:
        for case in args.cases:
            scene, sets = CASES[case]
            times: dict[str, list[tuple[float, float]]] = {"base": [], "this": []}
            _once(trees["this"], scene, sets, Path(tmp) / "warm")  # the form cache warm for both
            _once(trees["base"], scene, sets, Path(tmp) / "warm")
            for _ in range(args.rounds):
                for name, src in trees.items():
                    times[name].append(_once(src, scene, sets, Path(tmp) / name))
            row = {}
            for i, what in enumerate(("whole", "loop")):
                pairs = [a[i] / b[i] for a, b in zip(times["this"], times["base"], strict=True)]
                row[what] = {"base_median": statistics.median(t[i] for t in times["base"]),
                             "this_median": statistics.median(t[i] for t in times["this"]),
                             "ratio_median": statistics.median(pairs), "ratio_min": min(pairs),
                             "ratio_max": max(pairs)}
            results[case] = row
            print(f"{case}: whole {row['whole']['ratio_median']:.3f}, loop {row['loop']['ratio_median']:.3f}",
                  flush=True)
    args.output.mkdir(parents=True, exist_ok=True)
    (args.output / f"{args.name}.json").write_text(json.dumps({"base": str(args.base), "rounds": args.rounds,
                                                              "cases": results}, indent=1))
    lines = [f"# {args.name}: this tree against {args.base.name}, {args.rounds} alternated rounds", "",
             "`python scripts/same_speed.py " + shlex.join(argv if argv is not None else sys.argv[1:]) + "`", "",
             "| case | whole command: this / base (min–max) | time loop: this / base (min–max) | base whole, loop (s) |",
             "|---|---|---|---|"]
    for case, row in results.items():
        w, lo = row["whole"], row["loop"]
        lines.append(f"| {case} | {w['ratio_median']:.3f} ({w['ratio_min']:.2f}–{w['ratio_max']:.2f}) | "
                     f"{lo['ratio_median']:.3f} ({lo['ratio_min']:.2f}–{lo['ratio_max']:.2f}) | "
                     f"{w['base_median']:.2f}, {lo['base_median']:.2f} |")
    (args.output / f"{args.name}.md").write_text("\n".join(lines) + "\n")
    return 0


if __name__ == "__main__":
    sys.exit(main())
