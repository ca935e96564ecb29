"""How much each optional ingredient changes the answer (solver/run/accuracy/ingredients.py), per scene and
tolerance: the planner's report, without the run. Writes benchmarks/results/ingredients.md.

    python scripts/ingredients_report.py [--tol 1e-2] [--scenes example1 example2 example3 hard]
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

from mpi4py import MPI

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT))  # this checkout's solver, not an installed one


def main() -> int:
    from solver.config import load
    from solver.run import formcache
    from solver.run.accuracy import plan

    ap = argparse.ArgumentParser()
    ap.add_argument("--tol", type=float, default=1e-2)
    ap.add_argument("--scenes", nargs="+", default=["example1", "example2", "example3", "hard"])
    ap.add_argument("--output", default=str(ROOT / "benchmarks" / "results" / "ingredients.md"))
    args = ap.parse_args()
    formcache.install()
    lines = [f"# The ingredients' changes of the answer at TOL = {args.tol:g} (`python scripts/ingredients_report.py "
             f"--tol {args.tol:g}`)", "", "| scene | ingredient | change | / TOL | how |", "|---|---|---|---|---|"]
    for name in args.scenes:
        cfg = load(ROOT / "configs" / f"{name}.toml").replace(
            {"accuracy": {"tolerance": args.tol}, "output": {"xdmf": False}}, label="ingredients")
        t0 = time.perf_counter()
        p = plan(cfg, MPI.COMM_WORLD, log=lambda *a: None)
        print(f"{name}: planned in {time.perf_counter() - t0:.1f} s", flush=True)
        for i in p.ingredients:
            print("  " + i.line(p.tolerance), flush=True)
            lines.append(f"| {name} | {i.name} | {i.change:.2e} | {i.change / p.tolerance:.3g} | {i.how} |")
    if MPI.COMM_WORLD.rank == 0:
        Path(args.output).write_text("\n".join(lines) + "\n")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
