"""Example 1 at --tolerance 1e-4: where the command's time goes, and the error it achieves.

1. ``python -m solver run configs/example1.toml --tolerance TOL`` run ROUNDS times, alternated with
   ``python -c 'import solver.cli'`` (the import alone): wall seconds of each, the planning's seconds and its stages
   (plan.json) and the run's loop (the CLI's "done in"); median and range.
2. The achieved error: the plan's run against a reference (a P2 tolerance run at REF_TOL with a 4x smaller step,
   studies/tolerance.py's Reference.planned; its own error bounded by its estimate, and measured against a second
   reference at 3 REF_TOL).
Writes benchmarks/results/example1_tolerance.md (the machine is shared: compare the figures with each other).

    python scripts/example1_tolerance.py [--tol 1e-4] [--rounds 3] [--ref-tol 2e-5] [--no-error] [--against DIR]

``--against DIR``: the same command run from another checkout DIR (its own ``solver`` package) in every round,
alternated with this tree's, and its planning and whole command beside this tree's (per round ratios).
"""

from __future__ import annotations

import argparse
import json
import re
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT))


def timed(cmd: list[str], cwd: Path = ROOT) -> tuple[float, str]:
    t0 = time.perf_counter()
    out = subprocess.run(cmd, cwd=cwd, capture_output=True, text=True, check=True)
    return time.perf_counter() - t0, out.stdout + out.stderr


def spread(xs: list[float]) -> str:
    return f"{statistics.median(xs):.2f} ({min(xs):.2f}-{max(xs):.2f})"


def main() -> int:
    ap = argparse.ArgumentParser()
    ap.add_argument("--tol", type=float, default=1e-4)
    ap.add_argument("--rounds", type=int, default=3)
    ap.add_argument("--ref-tol", type=float, default=2e-5)
    ap.add_argument("--no-error", action="store_true")
    ap.add_argument("--against", default=None, help="another checkout whose command alternates with this tree's")
    ap.add_argument("--output", default=str(ROOT / "benchmarks" / "results" / "example1_tolerance.md"))
    args = ap.parse_args()
    py = sys.executable
    cmd = f"python -m solver run configs/example1.toml --tolerance {args.tol:g}"
    whole, imports, planning, loop, stages = [], [], [], [], []
    other: dict[str, list[float]] = {"whole": [], "planning": [], "loop": []}
    plans: list[dict] = []
    with tempfile.TemporaryDirectory() as tmp:
        command = [py, "-m", "solver", "run", "configs/example1.toml", "--tolerance", f"{args.tol:g}", "--output", tmp,
                   "--overwrite", "--no-progress", "--set", "output.xdmf=false"]
        def here() -> None:
            s, text = timed(command)
            whole.append(s)
            plan = json.loads((Path(tmp) / "plan.json").read_text())
            planning.append(plan["planning_seconds"])
            stages.append(plan["planning_stages"])
            plans.append(plan)
            # the CLI's "done in" counts from before the planning: the run is what it adds
            loop.append(float(re.search(r"done in ([0-9.]+) s", text).group(1)) - planning[-1])
            print(f"import {imports[-1]:.2f} s, command {whole[-1]:.2f} s, planning {planning[-1]:.2f} s, "
                  f"run {loop[-1]:.2f} s", flush=True)

        def there() -> None:
            s, text = timed(command, Path(args.against))
            other["whole"].append(s)
            other["planning"].append(json.loads((Path(tmp) / "plan.json").read_text())["planning_seconds"])
            other["loop"].append(float(re.search(r"done in ([0-9.]+) s", text).group(1)) - other["planning"][-1])
            print(f"  {args.against}: command {s:.2f} s, planning {other['planning'][-1]:.2f} s, run "
                  f"{other['loop'][-1]:.2f} s", flush=True)

        for r in range(args.rounds):
            s, _ = timed([py, "-c", "import solver.cli"])
            imports.append(s)
            # with another checkout, the order alternates too (this tree first in even rounds, the other in odd)
            for step in ((here, there) if r % 2 == 0 else (there, here)) if args.against else (here,):
                step()
    plan = plans[-1]
    ratio = [p / r for p, r in zip(planning, loop)]
    lines = [f"# Example 1 at `--tolerance {args.tol:g}` (`python scripts/example1_tolerance.py`)", "",
             f"{args.rounds} rounds, alternated with the import alone; median (range), seconds of wall time on a shared "
             "2-core machine (loaded: compare the figures with each other).", "",
             "| what | seconds |", "|---|---|",
             f"| `{cmd}` (whole command) | {spread(whole)} |",
             f"| `python -c 'import solver.cli'` | {spread(imports)} |",
             f"| planning (plan.json) | {spread(planning)} |",
             f"| the run it chose (the CLI's \"done in\" less the planning: the model's build and the loop) "
             f"| {spread(loop)} |",
             f"| planning / run | {spread(ratio)} |", "",
             *([f"The same command from `{args.against}`, alternated with this tree's in every round (this tree first in "
                "the 1st, 3rd, ... round, second in the others):", "",
                "| what | seconds | this tree / it, per round |", "|---|---|---|",
                f"| whole command | {spread(other['whole'])} | "
                f"{spread([a / b for a, b in zip(whole, other['whole'])])} |",
                f"| planning | {spread(other['planning'])} | "
                f"{spread([a / b for a, b in zip(planning, other['planning'])])} |",
                f"| the run | {spread(other['loop'])} | {spread([a / b for a, b in zip(loop, other['loop'])])} |",
                f"| planning / run | {spread([p / r for p, r in zip(other['planning'], other['loop'])])} | |", ""]
               if args.against else []),
             "Planning stages (last round): " + ", ".join(f"{k} {v:.2f} s" for k, v in stages[-1].items()), "",
             "Its solves on adapted meshes (P degree, cells: seconds of the refinement, the solve and the estimate; "
             "the degree's choice, the calibration and zeta's runs are their own stages): "
             + ", ".join(f"P{r['degree']} {r['cells']}: {r['seconds']:.2f} s" for r in plan["adaptation"]
                         if "seconds" in r), "",
             f"Plan: P{plan['u_degree']}, order {plan['order']}, k = {plan['k']:g}, {plan['cells']} cells; estimate "
             f"{sum(plan['estimate'].values()):.3e} ({', '.join(f'{k} {v:.2e}' for k, v in plan['estimate'].items())});"
             f" C = {plan['C']:.3g} (calibration: {plan['calibration']})."]
    if not args.no_error:
        from mpi4py import MPI  # noqa: F401

        from studies.tolerance import Reference, scene, tolerance_run

        cfg = scene("example1")
        ref = Reference.planned(cfg, args.ref_tol, 4)
        second = Reference.planned(cfg, 3 * args.ref_tol, 4)
        check = ref.measure(second.build())
        rec = tolerance_run(ref, cfg, args.tol)
        lines += ["", f"Achieved error at TOL {args.tol:g}: **{rec['error']:.3e}** ({rec['error'] / args.tol:.2f} TOL; "
                  f"u {rec['error_u']:.2e}, zeta {rec['error_zeta']:.2e}, largest at t = {rec['t_max']:g}); the plan's "
                  f"estimate {rec['estimate']:.3e}.",
                  f"Reference: a P2 tolerance run at {args.ref_tol:g} with a 4x smaller step ({ref.cells} cells, "
                  f"{ref.dofs} dofs, k = {ref.k:g}, {ref.seconds:.0f} s); its estimate {ref.estimate:.2e} bounds its own "
                  f"error; a second reference at {3 * args.ref_tol:g} differs from it by {check['error']:.2e}."]
    Path(args.output).write_text("\n".join(lines) + "\n")
    print("\n".join(lines))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
