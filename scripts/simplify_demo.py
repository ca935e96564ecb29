"""accuracy.simplify on a scene where it leaves an ingredient out: both plans' runs judged against the full model's
reference, and their costs side by side (alternated rounds: full, simplified, full, simplified, ...).

    python scripts/simplify_demo.py [--scene example3] [--tol 1e-2] [--ref-tol 1e-3] [--rounds 2] [--cli-rounds 3]

Then the whole command, ``python -m solver run SCENE --tolerance TOL`` without and with ``--set
accuracy.simplify=true`` (no XDMF), CLI_ROUNDS times alternated: wall seconds of each, and the planning (plan.json).

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
    ap.add_argument("--cli-rounds", type=int, default=3)
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
    if args.cli_rounds > 0:
        lines += ["", *commands(args)]
    Path(args.output).write_text("\n".join(lines) + "\n")
    print("\n".join(lines))
    return 0


def commands(args: argparse.Namespace) -> list[str]:
    """The whole command without and with accuracy.simplify, alternated: wall seconds and plan.json's planning."""
    import json
    import subprocess
    import tempfile
    import time

    from studies.tolerance import SCENES

    path, changes = SCENES[args.scene]
    sets = ["output.xdmf=false", *(f"{k}.{kk}.{kkk}={json.dumps(v)}" for k, t in changes.items()
                                   for kk, tt in t.items() for kkk, v in tt.items())]
    base = [sys.executable, "-m", "solver", "run", str(path.relative_to(ROOT)), "--tolerance", f"{args.tol:g}",
            "--no-progress", "--overwrite"]
    seconds: dict[str, list[float]] = {"full": [], "simplify": []}
    planning: dict[str, list[float]] = {"full": [], "simplify": []}
    with tempfile.TemporaryDirectory() as tmp:
        for _ in range(args.cli_rounds):
            for name, extra in (("full", []), ("simplify", ["accuracy.simplify=true"])):
                cmd = [*base, "--output", tmp, *(x for s in [*sets, *extra] for x in ("--set", s))]
                t0 = time.perf_counter()
                subprocess.run(cmd, cwd=ROOT, capture_output=True, text=True, check=True)
                seconds[name].append(time.perf_counter() - t0)
                planning[name].append(json.loads((Path(tmp) / "plan.json").read_text())["planning_seconds"])
                print(f"  {name}: command {seconds[name][-1]:.2f} s, planning {planning[name][-1]:.2f} s", flush=True)

    def med(xs: list[float]) -> str:
        return f"{statistics.median(xs):.2f} ({min(xs):.2f}-{max(xs):.2f})"

    ratio = [s / f for f, s in zip(seconds["full"], seconds["simplify"])]
    shown = " ".join(base[1:5] + base[5:7])
    return [f"The whole command, `python {shown}` without and with `--set accuracy.simplify=true` (and "
            f"`--set output.xdmf=false`), {args.cli_rounds} rounds alternated; median (range), seconds:", "",
            "| command | whole command (s) | planning (plan.json, s) |", "|---|---|---|",
            f"| full | {med(seconds['full'])} | {med(planning['full'])} |",
            f"| simplify | {med(seconds['simplify'])} | {med(planning['simplify'])} |",
            f"| simplify / full, per round | {med(ratio)} | |"]


if __name__ == "__main__":
    raise SystemExit(main())
