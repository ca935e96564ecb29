"""Side-by-side benchmark of the contact methods on moving-contact levels (issue 31).

Runs each case with a baseline checkout's default Newton (+ fallback) and with this tree's ``solver.method``
values (``--methods``: newton_energy and newton_condensed), alternating them in one run (the machine is shared:
only the ratios of side-by-side medians mean something), and writes benchmarks/results/nonlinear_method.{json,md}:
total and largest per-level Newton iterations, levels above 10 iterations, factorizations, the time loop
(the sum of wall_time) and the largest relative differences of the contact force, ||eps(u)|| and ||zeta||.

    python scripts/nonlinear_bench.py --base CHECKOUT_OF_e693721 --pairs 2
"""

from __future__ import annotations

import argparse
import csv
import json
import os
import shlex
import subprocess
import sys
import tempfile
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
P2 = ["discretization.u_degree=2", "discretization.zeta_degree=2", "time.order=2"]
CASES = {
    "hard n=48 P2 order 2 k=0.0125": ("hard.toml", [*P2, "mesh.nx=48", "mesh.ny=48", "time.k=0.0125"]),
    "load_cycle n=32 P2 order 2": ("load_cycle.toml", [*P2, "mesh.nx=32", "mesh.ny=32"]),
    "hard n=16 P1": ("hard.toml", []),
    "hard n=32 P1": ("hard.toml", ["mesh.nx=32", "mesh.ny=32"]),
    "hard n=16 P2 order 2": ("hard.toml", P2),
    "hard n=32 P2 order 2": ("hard.toml", [*P2, "mesh.nx=32", "mesh.ny=32"]),
    "hard n=64 P1": ("hard.toml", ["mesh.nx=64", "mesh.ny=64"]),
    "hard n=64 P2 order 2": ("hard.toml", [*P2, "mesh.nx=64", "mesh.ny=64"]),
}


def run(src: Path, scene: str, sets: list[str], method: str | None, out: Path) -> dict:
    """One run of ``scene`` with the code in ``src``; its figures from timeseries.csv."""
    extra = [*sets, f"solver.method='{method}'"] if method else sets
    cmd = [sys.executable, "-m", "solver", "run", str(ROOT / "configs" / scene), "--no-progress", "--overwrite",
           "--output", str(out), *[a for s in extra for a in ("--set", s)]]
    proc = subprocess.run(cmd, cwd=src, capture_output=True, text=True)
    rows = list(csv.DictReader(open(out / "timeseries.csv"))) if (out / "timeseries.csv").exists() else []
    its = [int(r["newton_iterations"]) for r in rows]
    return {"ok": proc.returncode == 0, "levels": len(rows), "iterations": sum(its), "max_level": max(its, default=0),
            "levels_over_10": sum(i > 10 for i in its), "factorizations": sum(int(r["factorizations"]) for r in rows),
            "time_loop": sum(float(r["wall_time"]) for r in rows),
            "force": [float(r["contact_force"]) for r in rows], "strain": [float(r["strain_norm"]) for r in rows],
            "zeta": [float(r["zeta_norm"]) for r in rows]}


def rel_diff(a: list[float], b: list[float]) -> float:
    """The largest difference over the levels both ran, relative to the largest value of a."""
    fa, fb = np.array(a), np.array(b)
    n = min(len(fa), len(fb))
    return float(np.max(np.abs(fa[:n] - fb[:n])) / max(np.max(np.abs(fa[:n])), 1e-300)) if n else float("nan")


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--base", type=Path, required=True, help="checkout of the baseline code")
    ap.add_argument("--base-method", help="the baseline's solver.method (default: the checkout's default); with "
                    "--base . a method of this tree against others")
    ap.add_argument("--pairs", type=int, default=1, help="rounds (base, then each method) of the first case")
    ap.add_argument("--pairs-rest", type=int, default=1, help="rounds of the other cases")
    ap.add_argument("--cases", nargs="+", default=list(CASES), choices=list(CASES))
    ap.add_argument("--methods", nargs="+", default=["newton_energy", "newton_condensed"],
                    help="this tree's solver.method values run beside the baseline")
    ap.add_argument("--name", default="nonlinear_method", help="the results' file stem in benchmarks/results")
    args = ap.parse_args()
    results = {}
    sides = ["base", *args.methods]
    with tempfile.TemporaryDirectory() as tmp:
        for i, name in enumerate(args.cases):
            scene, sets = CASES[name]
            runs: dict[str, list[dict]] = {side: [] for side in sides}
            for p in range(args.pairs if i == 0 else args.pairs_rest):
                for side in sides:  # alternated: base, m1, m2, base, m1, m2, ...
                    src, method = (args.base, args.base_method) if side == "base" else (ROOT, side)
                    runs[side].append(run(src, scene, sets, method, Path(tmp) / f"{side}{i}{p}"))
            base = runs["base"][0]
            r = {**runs, "diff": {}, "time_ratio": {}}
            for m in args.methods:
                x = runs[m][0]
                r["diff"][m] = {k: rel_diff(base[k], x[k]) for k in ("force", "strain", "zeta")}
                r["time_ratio"][m] = float(np.median([y["time_loop"] for y in runs[m]]) /
                                           np.median([y["time_loop"] for y in runs["base"]]))
            results[name] = r
            print(name, r["time_ratio"], r["diff"], flush=True)
    for r in results.values():
        for side in sides:
            for x in r[side]:
                for k in ("force", "strain", "zeta"):
                    x.pop(k)
    out = ROOT / "benchmarks" / "results"
    (out / f"{args.name}.json").write_text(json.dumps(results, indent=1))
    base = f"{args.base_method} at {args.base}" if args.base_method else "Newton (+ fallback) at the baseline"
    lines = [f"# Moving-contact levels: {base} against this tree's methods",
             "", f"`python scripts/nonlinear_bench.py {shlex.join(sys.argv[1:])}`; "
             f"{os.cpu_count()} cores, shared. Medians of the time loop (sum of wall_time), runs alternated "
             "(base, then each method, repeated). Ratio: of the base's time loop; diff: the largest difference over "
             "the levels of the contact force, ||eps(u)|| and ||zeta||, relative to the base's largest value.", "",
             "| case | method | ok | iterations | max/level | levels > 10 | factorizations | time loop (s) | ratio |"
             " diff force, strain, zeta |",
             "|---|---|---|---|---|---|---|---|---|---|"]
    for name, r in results.items():
        for side in sides:
            x = r[side][0]
            t = np.median([y["time_loop"] for y in r[side]])
            ratio = f"{r['time_ratio'][side]:.2f}" if side != "base" else ""
            diff = ", ".join(f"{v:.1e}" for v in r["diff"][side].values()) if side != "base" else ""
            lines.append(f"| {name} | {side} | {x['ok']} | {x['iterations']} | {x['max_level']} | "
                         f"{x['levels_over_10']} | {x['factorizations']} | {t:.2f} | {ratio} | {diff} |")
    (out / f"{args.name}.md").write_text("\n".join(lines) + "\n")


if __name__ == "__main__":
    main()
