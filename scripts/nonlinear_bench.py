"""Side-by-side benchmark of the contact methods on moving-contact levels (issue 31).

Runs each case with a baseline checkout's default Newton (+ fallback) and with this tree's
``solver.method = "newton_energy"``, alternating A B A B in one run (the machine is shared: only the
ratios of side-by-side medians mean something), and writes benchmarks/results/nonlinear_method.{json,md}:
total and largest per-level Newton iterations, levels above 10 iterations, factorizations, the time loop
(the sum of wall_time) and the largest relative difference of the contact force over the levels.

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
            "force": [float(r["contact_force"]) for r in rows]}


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--base", type=Path, required=True, help="checkout of the baseline code")
    ap.add_argument("--pairs", type=int, default=1, help="A B pairs of the first case")
    ap.add_argument("--pairs-rest", type=int, default=1, help="A B pairs of the other cases")
    ap.add_argument("--cases", nargs="+", default=list(CASES), choices=list(CASES))
    ap.add_argument("--name", default="nonlinear_method", help="the results' file stem in benchmarks/results")
    args = ap.parse_args()
    results = {}
    with tempfile.TemporaryDirectory() as tmp:
        for i, name in enumerate(args.cases):
            scene, sets = CASES[name]
            pairs = args.pairs if i == 0 else args.pairs_rest
            a, b = [], []
            for p in range(pairs):
                a.append(run(args.base, scene, sets, None, Path(tmp) / f"a{i}{p}"))
                b.append(run(ROOT, scene, sets, "newton_energy", Path(tmp) / f"b{i}{p}"))
            fa, fb = np.array(a[0]["force"]), np.array(b[0]["force"])
            n = min(len(fa), len(fb))
            diff = float(np.max(np.abs(fa[:n] - fb[:n]) / np.maximum(np.abs(fa[:n]), 1e-300 + np.max(np.abs(fa)))))
            results[name] = {"base": a, "newton_energy": b, "force_max_rel_diff": diff,
                             "time_ratio": float(np.median([y["time_loop"] for y in b]) /
                                                 np.median([x["time_loop"] for x in a]))}
            print(name, {k: v for k, v in results[name].items() if k not in ("base", "newton_energy")}, flush=True)
    out = ROOT / "benchmarks" / "results"
    for side in ("base", "newton_energy"):
        for r in results.values():
            for x in r[side]:
                x.pop("force")
    (out / f"{args.name}.json").write_text(json.dumps(results, indent=1))
    lines = ["# Moving-contact levels: Newton (+ fallback) at the baseline against newton_energy",
             "", f"`python scripts/nonlinear_bench.py {shlex.join(sys.argv[1:])}`; "
             f"{os.cpu_count()} cores, shared. Medians of the time loop (sum of wall_time), A B alternated.", "",
             "| case | method | ok | iterations | max/level | levels > 10 | factorizations | time loop (s) |",
             "|---|---|---|---|---|---|---|---|"]
    for name, r in results.items():
        for side in ("base", "newton_energy"):
            x = r[side][0]
            t = np.median([y["time_loop"] for y in r[side]])
            lines.append(f"| {name} | {side} | {x['ok']} | {x['iterations']} | {x['max_level']} | "
                         f"{x['levels_over_10']} | {x['factorizations']} | {t:.2f} |")
        lines.append(f"| {name} | ratio, force diff | | | | | | {r['time_ratio']:.2f}, "
                     f"{r['force_max_rel_diff']:.1e} |")
    (out / f"{args.name}.md").write_text("\n".join(lines) + "\n")


if __name__ == "__main__":
    main()
