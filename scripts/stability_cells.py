"""Stability-map cells of the hard scene for one displacement method beside Newton's recorded cells (issue 31).

The stability map (``python -m studies study stability``) also needs the fine reference runs of each scene for its
error columns; this runs only the cells (``configs/hard.toml``, mu in --mus, n in --ns, k in --ks, max_it 200 as in
the map) and reports whether each level converged, with the iterations and factorizations, next to the rows of
``newton`` in benchmarks/results/stability.csv. Writes benchmarks/results/stability_cells_<method>.md.

    python scripts/stability_cells.py --method newton_condensed
"""

from __future__ import annotations

import argparse
import csv
import subprocess
import sys
import tempfile
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]


def cell(method: str, mu: str, n: int, k: str, out: Path) -> dict:
    """One run of the cell; its status and figures from timeseries.csv."""
    sets = [f"solver.method='{method}'", f"boundary.bottom.mu={mu}", f"mesh.nx={n}", f"mesh.ny={n}", f"time.k={k}",
            "solver.max_it=200", "output.xdmf=false", "output.every=100000"]
    cmd = [sys.executable, "-m", "solver", "run", str(ROOT / "configs" / "hard.toml"), "--no-progress", "--overwrite",
           "--output", str(out), *[a for s in sets for a in ("--set", s)]]
    proc = subprocess.run(cmd, cwd=ROOT, capture_output=True, text=True)
    rows = list(csv.DictReader(open(out / "timeseries.csv"))) if (out / "timeseries.csv").exists() else []
    its = [int(r["newton_iterations"]) for r in rows] or [0]
    return {"status": "converged" if proc.returncode == 0 else f"failed ({proc.returncode})", "levels": len(rows),
            "per_step": sum(its) / len(its), "max": max(its), "factorizations": sum(int(r["factorizations"]) for r in rows)}


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--method", default="newton_condensed")
    ap.add_argument("--mus", nargs="+", default=["1e-10", "1e-12"])
    ap.add_argument("--ns", type=int, nargs="+", default=[8, 16])
    ap.add_argument("--ks", nargs="+", default=["0.1", "0.05", "0.01", "0.005", "0.001", "0.0005"])
    args = ap.parse_args()
    recorded = {(r["mu"], r["n"], r["k"]): r for r in csv.DictReader(open(ROOT / "benchmarks/results/stability.csv"))
                if r["scene"] == "hard" and r["method"] == "newton"}
    lines = [f"# Stability-map cells of hard.toml: {args.method} beside newton", "",
             f"`python scripts/stability_cells.py {' '.join(sys.argv[1:])}`; newton's columns from "
             "benchmarks/results/stability.csv (max_it 200 in both).", "",
             "| mu | n | k | newton | its/step | max | factorizations | "
             f"{args.method} | its/step | max | factorizations |", "|---|---|---|---|---|---|---|---|---|---|---|"]
    with tempfile.TemporaryDirectory() as tmp:
        for mu in args.mus:
            for n in args.ns:
                for k in args.ks:
                    x = cell(args.method, mu, n, k, Path(tmp) / f"{mu}-{n}-{k}")
                    ref = recorded.get((str(float(mu)), str(n), str(float(k))), {})
                    line = (f"| {mu} | {n} | {k} | {ref.get('status', '-')} | "
                            f"{float(ref.get('iterations_per_step', 'nan')):.2f} | {ref.get('max_iterations', '-')} | "
                            f"{ref.get('factorizations', '-')} | {x['status']} | {x['per_step']:.2f} | {x['max']} | "
                            f"{x['factorizations']} |")
                    print(line, flush=True)
                    lines.append(line)
    out = ROOT / "benchmarks" / "results" / f"stability_cells_{args.method}.md"
    out.write_text("\n".join(lines) + "\n")
    print(f"wrote {out}")


if __name__ == "__main__":
    main()
