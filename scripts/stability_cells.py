"""Stability cells where plain Newton fails: hard.toml with P2 u and zeta and the second-order scheme (issue 31).

The stability map (``python -m studies study stability``) sweeps P1 meshes, where no level of the hard scene needs
Newton's fallback. With P2 the contact zone's edge moves by several points per level and plain semismooth Newton
cycles between active sets. This runs the Newton family over mu, n and k on that scene, each cell as a CLI run
(max_it 200, as in the map): plain Newton (``solver.newton_fallback = false``), Newton with its fallback (the
default), ``newton_energy`` and ``newton_condensed``, and writes benchmarks/results/stability_p2.{csv,md} and one
heat map per method (stability_p2_<method>.png): whether each run reached T, iterations per step, the largest
per level, factorizations. Iterations only: no error column (the map's references are P1).

    python scripts/stability_cells.py            # about 10 minutes on 2 cores
"""

from __future__ import annotations

import argparse
import csv
import subprocess
import sys
import tempfile
from concurrent.futures import ThreadPoolExecutor
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))
P2 = ["discretization.u_degree=2", "discretization.zeta_degree=2", "time.order=2"]
METHODS = {  # label -> overrides
    "newton_plain": ["solver.method='newton'", "solver.newton_fallback=false"],
    "newton": ["solver.method='newton'"],
    "newton_energy": ["solver.method='newton_energy'"],
    "newton_condensed": ["solver.method='newton_condensed'"],
    "auto": ["solver.method='auto'"],
}
COLUMNS = ["scene", "method", "mu", "n", "k", "status", "reason", "levels", "iterations_per_step", "max_iterations",
           "factorizations", "zeta_left_range"]


def cell(label: str, mu: float, n: int, k: float, tmp: Path) -> dict:
    """One run of the cell; its status and figures from timeseries.csv (and the one-line error of a failure)."""
    out = tmp / f"{label}-{mu}-{n}-{k}"
    sets = [*P2, *METHODS[label], f"boundary.bottom.mu={mu!r}", f"mesh.nx={n}", f"mesh.ny={n}", f"time.k={k!r}",
            "solver.max_it=200", "output.xdmf=false", "output.every=100000"]
    cmd = [sys.executable, "-m", "solver", "run", str(ROOT / "configs" / "hard.toml"), "--no-progress", "--overwrite",
           "--output", str(out), *[a for s in sets for a in ("--set", s)]]
    proc = subprocess.run(cmd, cwd=ROOT, capture_output=True, text=True)
    rows = list(csv.DictReader(open(out / "timeseries.csv"))) if (out / "timeseries.csv").exists() else []
    its = [int(r["newton_iterations"]) for r in rows[1:]] or [0]
    lines = proc.stderr.strip().splitlines()
    return {"scene": "hard_p2", "method": label, "mu": mu, "n": n, "k": k,
            "status": "converged" if proc.returncode == 0 else "failed",
            "reason": "" if proc.returncode == 0 else (lines[-1] if lines else f"exit {proc.returncode}"),
            "levels": len(rows), "iterations_per_step": sum(its) / len(its), "max_iterations": max(its),
            "factorizations": sum(int(r["factorizations"]) for r in rows),
            "zeta_left_range": any(int(r["zeta_clipped"]) > 0 for r in rows)}


def _range(rows: list[dict], key: str, fmt: str) -> str:
    """'low – high' of a column over the rows ('-' for none)."""
    if not rows:
        return "-"
    return f"{fmt.format(min(r[key] for r in rows))} – {fmt.format(max(r[key] for r in rows))}"


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--methods", nargs="+", default=list(METHODS), choices=list(METHODS))
    ap.add_argument("--mus", type=float, nargs="+", default=[1e-4, 1e-6, 1e-8, 1e-10, 1e-12])
    ap.add_argument("--ns", type=int, nargs="+", default=[16, 32])
    ap.add_argument("--ks", type=float, nargs="+", default=[0.05, 0.025, 0.0125])
    ap.add_argument("--jobs", type=int, default=2, help="runs in parallel")
    ap.add_argument("--output", default=str(ROOT / "benchmarks" / "results"))
    args = ap.parse_args()
    out = Path(args.output)
    cells = [(m, mu, n, k) for m in args.methods for mu in args.mus for n in args.ns for k in args.ks]
    with tempfile.TemporaryDirectory() as tmp, ThreadPoolExecutor(args.jobs) as pool:
        rows = list(pool.map(lambda c: cell(*c, Path(tmp)), cells))
    with open(out / "stability_p2.csv", "w", newline="") as fh:
        w = csv.DictWriter(fh, fieldnames=COLUMNS)
        w.writeheader()
        w.writerows(rows)
    lines = ["# Stability cells of hard.toml with P2 u and zeta, order 2: the Newton family", "",
             f"`python scripts/stability_cells.py {' '.join(sys.argv[1:])}`; each cell a CLI run to T = 1 with "
             "max_it 200. newton_plain: Newton without its fallback (solver.newton_fallback = false).", "",
             "| method | reached T | failed | its/step (range) | max its on a level | factorizations (range) |",
             "|---|---|---|---|---|---|"]
    for label in args.methods:
        sub = [r for r in rows if r["method"] == label]
        ok = [r for r in sub if r["status"] == "converged"]
        lines.append(f"| {label} | {len(ok)} of {len(sub)} | {len(sub) - len(ok)} | "
                     f"{_range(ok, 'iterations_per_step', '{:.2f}')} | "
                     f"{max((r['max_iterations'] for r in ok), default='-')} | {_range(ok, 'factorizations', '{:d}')} |")
    lines += ["", "| mu | n | k | " + " | ".join(f"{m}: its/step, max, factorizations" for m in args.methods) + " |",
              "|---|---|---|" + "---|" * len(args.methods)]
    index = {(r["method"], r["mu"], r["n"], r["k"]): r for r in rows}
    for mu in args.mus:
        for n in args.ns:
            for k in args.ks:
                parts = []
                for m in args.methods:
                    r = index[(m, mu, n, k)]
                    parts.append(f"{r['iterations_per_step']:.2f}, {r['max_iterations']}, {r['factorizations']}"
                                 if r["status"] == "converged" else f"**failed** at level {r['levels']}")
                lines.append(f"| {mu:g} | {n} | {k:g} | " + " | ".join(parts) + " |")
    failed = [r for r in rows if r["status"] != "converged"]
    if failed:
        lines += ["", "Failures (the run's one-line error):", ""]
        lines += [f"- {r['method']}, mu = {r['mu']:g}, n = {r['n']}, k = {r['k']:g}: {r['reason']}" for r in failed]
    (out / "stability_p2.md").write_text("\n".join(lines) + "\n")
    try:
        from studies.study import heatmaps

        for path in heatmaps(rows, out, prefix="stability_p2"):
            print(path)
    except ImportError as exc:  # the plotting stack is optional (PLOTS=0)
        print(f"no heat maps: {exc}")
    print(f"wrote {out / 'stability_p2.md'} and stability_p2.csv")


if __name__ == "__main__":
    main()
