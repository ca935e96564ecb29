"""accuracy.simplify on a scene where it leaves an ingredient out: both plans' runs judged against the full model's
reference, and their costs side by side (alternated rounds: full, simplified, full, simplified, ...).

    python scripts/simplify_demo.py [--scene example3] [--tol 1e-2] [--ref-tol 1e-3] [--rounds 2]

Writes benchmarks/results/simplify.md (a shared 2-core machine: compare the figures with each other).
"""

from __future__ import annotations

import argparse
import statistics
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT))


def main() -> int:
    from solver.run import formcache
    from studies.tolerance import Reference, scene, tolerance_run

    ap = argparse.ArgumentParser()
    ap.add_argument("--scene", default="example3")
    ap.add_argument("--tol", type=float, default=1e-2)
    ap.add_argument("--ref-tol", type=float, default=1e-3)
    ap.add_argument("--rounds", type=int, default=2)
    ap.add_argument("--output", default=str(ROOT / "benchmarks" / "results" / "simplify.md"))
    args = ap.parse_args()
    formcache.install()
    full = scene(args.scene)
    simple = full.replace({"accuracy": {"simplify": True}}, label="simplify")
    ref = Reference.planned(full, args.ref_tol, 4)
    runs = {"full": [], "simplify": []}
    tolerance_run(ref, full, args.tol, log=lambda *a: None)  # forms compiled before anything is timed
    tolerance_run(ref, simple, args.tol, log=lambda *a: None)
    for _ in range(args.rounds):
        for name, cfg in (("full", full), ("simplify", simple)):
            runs[name].append(tolerance_run(ref, cfg, args.tol))
    lines = [f"# `accuracy.simplify` on {args.scene} at TOL {args.tol:g} (`python scripts/simplify_demo.py --scene "
             f"{args.scene} --tol {args.tol:g}`)", "",
             f"Both judged against the full model's reference (a P2 tolerance run at {args.ref_tol:g}, 4x smaller step, "
             f"{ref.cells} cells; its estimate {ref.estimate:.2e}). {args.rounds} alternated rounds; median (range) of "
             "the seconds on a shared, loaded 2-core machine.", "",
             "| plan | left out | chosen | error | error / TOL | planning (s) | loop (s) | cost (s) |",
             "|---|---|---|---|---|---|---|---|"]
    for name, rs in runs.items():
        r = rs[-1]

        def med(key: str, rs=rs) -> str:
            xs = [x[key] for x in rs]
            return f"{statistics.median(xs):.2f} ({min(xs):.2f}-{max(xs):.2f})"

        lines.append(f"| {name} | {', '.join(r['left_out']) or '—'} | P{r['degree']} o{r['order']} k={r['k']:g}, "
                     f"{r['cells']} cells | {r['error']:.2e} | {r['error'] / args.tol:.2f} | {med('planning_seconds')} "
                     f"| {med('loop_seconds')} | {med('cost')} |")
    save = [f["loop_seconds"] / s["loop_seconds"] for f, s in zip(runs["full"], runs["simplify"])]
    lines += ["", "Loop of the full plan over the simplified one's, per round: "
              + ", ".join(f"{x:.2f}" for x in save)]
    Path(args.output).write_text("\n".join(lines) + "\n")
    print("\n".join(lines))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
