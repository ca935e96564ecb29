"""Reusing the displacement's preconditioner in 3-D Example 1 (issue 30): what the iterative path reuses, measured.

    python scripts/pc_reuse.py [--sizes 14 22] [--steps 5] [--repeats 2] [--out benchmarks/results]

The Jacobian J = K + C(active set) is modified only when the contact active set changes (physics/displacement.py),
so PETSc sets the multigrid preconditioner up again only then: in 3-D Example 1 twice, both at level 0 (K, then
K + C), never in the steps (tests/solvers/test_linear.py counts PETSc's PCSetUp events). What is left to reuse is
level 0's second set-up: ML's ``pc_ml_reuse_interpolation`` keeps the first hierarchy's aggregates and
interpolation (built on K, without contact) and only recomputes the coarse operators of K + C. Each variant runs
the CLI (``solver.linear = "iterative"``, nothing written but the CSV) in its own process, alternated; reported:
level 0's time, the time of a displacement step (median over the steps after step 1), the Krylov iterations per
solve at level 0 and per step, the set-ups, and the contact force (the solutions agree to the solver tolerance).
Writes ``pc_reuse.json`` and ``pc_reuse.md``.
"""

from __future__ import annotations

import argparse
import csv
import json
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
VARIANTS = {
    "default": [],
    "ml-reuse-interpolation": ["solver.petsc_options.mech_pc_ml_reuse_interpolation=true"],
}


def _case(n: int, variant: str, steps: int, out: Path) -> dict:
    sets = [f"mesh.nx={n}", f"mesh.ny={n}", f"mesh.nz={n}", f"time.T={steps * 0.02!r}", "solver.linear=iterative",
            "output.xdmf=false", "output.checkpoint_every=0", *VARIANTS[variant]]
    cmd = [sys.executable, "-m", "solver", "run", "configs/example1_3d.toml", *(a for s in sets for a in ("--set", s)),
           "--no-progress", "--output", str(out)]
    subprocess.run(cmd, cwd=ROOT, check=True, capture_output=True)
    rows = list(csv.DictReader(open(out / "timeseries.csv")))
    return {"level0": float(rows[0]["wall_time"]),
            "step": statistics.median(float(r["time_displacement"]) for r in rows[2:]),
            "its_level0": int(rows[0]["krylov_iterations"]) / int(rows[0]["linear_solves"]),
            "its_step": statistics.mean(int(r["krylov_iterations"]) / int(r["linear_solves"]) for r in rows[1:]),
            "setups": sum(int(r["factorizations"]) for r in rows), "contact_force": float(rows[-1]["contact_force"])}


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--sizes", type=int, nargs="+", default=[14, 22])
    p.add_argument("--steps", type=int, default=5)
    p.add_argument("--repeats", type=int, default=2)
    p.add_argument("--out", type=Path, default=ROOT / "benchmarks" / "results")
    args = p.parse_args(argv)
    runs: dict[str, list[dict]] = {}
    with tempfile.TemporaryDirectory() as tmp:
        for r in range(args.repeats):
            for n in args.sizes:
                for variant in VARIANTS:
                    key = f"n={n} {variant}"
                    runs.setdefault(key, []).append(_case(n, variant, args.steps, Path(tmp) / f"{key}-{r}"))
                    print(key, r, runs[key][-1], flush=True)
    med = {key: {k: statistics.median(x[k] for x in rs) for k in rs[0]} for key, rs in runs.items()}
    result = {"steps": args.steps, "repeats": args.repeats, "median": med, "runs": runs,
              "date": time.strftime("%Y-%m-%d %H:%M UTC", time.gmtime())}
    args.out.mkdir(parents=True, exist_ok=True)
    (args.out / "pc_reuse.json").write_text(json.dumps(result, indent=1) + "\n")
    lines = [f"# Preconditioner reuse, 3-D Example 1, iterative path ({result['date']})", "",
             f"`python scripts/pc_reuse.py --sizes {' '.join(map(str, args.sizes))} --steps {args.steps} "
             f"--repeats {args.repeats}`: one rank, medians; times on a shared 2-core machine (read the ratios).", "",
             "| n (dofs) | variant | level 0 (s) | displacement / step (s) | Krylov its / solve, level 0 | "
             "Krylov its / solve, steps | PC set-ups | contact force at T |", "|---|---|---|---|---|---|---|---|"]
    for n in args.sizes:
        for variant in VARIANTS:
            m = med[f"n={n} {variant}"]
            lines.append(f"| {n} ({3 * (n + 1) ** 3:,}) | {variant} | {m['level0']:.2f} | {m['step']:.3f} | "
                         f"{m['its_level0']:.1f} | {m['its_step']:.1f} | {m['setups']:.0f} | {m['contact_force']:.10g} |")
    (args.out / "pc_reuse.md").write_text("\n".join(lines) + "\n")
    print("\n".join(lines))
    return 0


if __name__ == "__main__":
    sys.exit(main())
