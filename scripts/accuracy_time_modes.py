"""accuracy.time = "uniform" (step doubling) against "adaptive" (the run's step controller): each scene's plan and
run at a tolerance, both judged against one fine reference, the cases alternated (uniform, adaptive, uniform, ...).

The reference is a P2 tolerance run at REF_TOL (studies/tolerance.py's Reference) whose step is made a divisor of
T / CHECKS, so that it has a level at every check time t = j T / CHECKS. The uniform plan's run is compared at each of
its levels the reference has (the check times among them where its step divides them); the adaptive run lands on the
check times (``output.times``, added to the plan's run only) and is compared there. Planning and the run are timed in
the process (the forms compiled by a first round that is not counted).

    python scripts/accuracy_time_modes.py [--scenes example3 example2] [--tol 1e-2] [--ref-tol 1e-3] [--rounds 2]
        [--set KEY=VALUE ...]

Writes benchmarks/results/accuracy_time_modes.md (a shared 2-core machine: compare the figures with each other).
"""

from __future__ import annotations

import argparse
import gc
import math
import statistics
import sys
import time
from pathlib import Path

from mpi4py import MPI

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT))

CHECKS = 10  # the check times j T / CHECKS


def reference(cfg, ref_tol: float):
    """The reference: a P2 plan at ``ref_tol`` run at a quarter of its step or less, a divisor of T / CHECKS."""
    from solver.run.accuracy import plan
    from studies.tolerance import MAX_DOFS, Reference, quiet

    t0 = time.perf_counter()
    p = plan(quiet(cfg).replace({"accuracy": {"tolerance": ref_tol, "degrees": [2], "max_dofs": MAX_DOFS}},
                                label="reference"), MPI.COMM_SELF, log=lambda *a: None)
    T = cfg.time.T
    n = CHECKS * math.ceil(T / (p.k / 4) / CHECKS - 1e-9)
    ref = Reference(cfg, p.changes, T / n, p.geo, f"TOL {ref_tol:g}, P2 order {p.order}", p.estimate.total)
    ref.seconds = time.perf_counter() - t0
    return ref


def measure(ref, model, planning: float) -> dict:
    """The run of ``model`` against ``ref`` (studies/tolerance.py's Reference.measure, which it follows) with its
    steps and rejected trials counted."""
    import numpy as np

    from solver.run.stepper import levels
    from studies.reference import PointwiseError

    judge = PointwiseError(ref.model.u.function_space, ref.model.damage.V if ref.model.damage is not None else None,
                           model)
    errs, loop, steps, rejected = [], 0.0, 0, 0
    for row in levels(model):
        loop += row["wall_time"]
        steps, rejected = row["step"], rejected + int(row.get("rejected", 0))
        j = ref.level(row["t"])
        if j is not None:
            errs.append(sum(judge(ref.u[j], ref.zeta[j])))
    return {"error": float(np.max(errs)), "levels": len(errs), "loop_seconds": loop, "cost": loop + planning,
            "steps": steps, "rejected": rejected, "failure": None}


def one(ref, cfg, tol: float, mode: str) -> dict:
    """Plan at ``tol`` with accuracy.time = ``mode`` and run it against ``ref``."""
    from solver.run.accuracy import plan
    from solver.run.model import build_model
    from studies.tolerance import MAX_DOFS, quiet

    t0 = time.perf_counter()
    p = plan(cfg.replace({"accuracy": {"tolerance": tol, "max_dofs": MAX_DOFS, "time": mode}}, label=mode),
             MPI.COMM_SELF, log=lambda *a: None)
    planning = time.perf_counter() - t0
    run_cfg = quiet(p.config)
    if p.adaptive:
        T = run_cfg.time.T
        run_cfg = run_cfg.replace({"output": {"times": [j * T / CHECKS for j in range(1, CHECKS + 1)]}},
                                  label="check times")
    model = build_model(run_cfg, MPI.COMM_SELF, p.geo)
    rec = measure(ref, model, planning)
    out = {"mode": mode, "degree": p.degree, "k": p.k, "cells": p.geo.num_cells(), "planning": planning,
           "loop": rec["loop_seconds"], "steps": rec["steps"], "rejected": rec["rejected"], "cost": rec["cost"],
           "error": rec["error"], "compared": rec["levels"],
           "estimate": p.estimate.total, "time_part": p.estimate.time, "stages": dict(p.stages),
           "failure": rec["failure"]}
    del model, p
    gc.collect()
    return out


def main() -> int:
    from solver.run import formcache
    from studies.tolerance import scene

    ap = argparse.ArgumentParser()
    ap.add_argument("--scenes", nargs="+", default=["example3", "example2"])
    ap.add_argument("--tol", type=float, default=1e-2)
    ap.add_argument("--ref-tol", type=float, default=1e-3)
    ap.add_argument("--rounds", type=int, default=2)
    ap.add_argument("--set", dest="sets", action="append", default=[], help="KEY=VALUE, TOML value, for every scene")
    ap.add_argument("--output", default=str(ROOT / "benchmarks" / "results" / "accuracy_time_modes.md"))
    args = ap.parse_args()
    formcache.install()
    import tomllib

    from solver.config import merge

    changes: dict = {}
    for s in args.sets:
        key, _, value = s.partition("=")
        *path, last = key.split(".")
        table: dict = {last: tomllib.loads(f"v = {value}")["v"]}
        for part in reversed(path):
            table = {part: table}
        changes = merge(changes, table)
    cmd = (f"python scripts/accuracy_time_modes.py --scenes {' '.join(args.scenes)} --tol {args.tol:g} --ref-tol "
           f"{args.ref_tol:g} --rounds {args.rounds}" + "".join(f" --set {s}" for s in args.sets))
    lines = [f"# accuracy.time: uniform (step doubling) against adaptive (the run's step controller) at TOL {args.tol:g}",
             "", f"`{cmd}`", "",
             f"{args.rounds} alternated rounds (uniform, adaptive, ...) after one uncounted round; median (range) of "
             "the seconds on a shared, loaded 2-core machine. Error: max over the compared levels of the paper's norm "
             f"against the reference (a P2 tolerance run at {args.ref_tol:g}, step a quarter of its plan's or less, "
             f"with a level at every t = j T / {CHECKS}); the adaptive run lands on those check times, the uniform "
             "run is compared at every level of its own the reference has.", "",
             "| scene | time | chosen | steps (rejected) | error | error / TOL | compared levels | planning (s) | run (s) "
             "| plan + run (s) | (plan + run) / uniform's |", "|---|---|---|---|---|---|---|---|---|---|---|"]
    for name in args.scenes:
        cfg = scene(name).replace(changes, label="--set") if changes else scene(name)
        ref = reference(cfg, args.ref_tol)
        print(f"{name}: reference {ref.cells} cells, k = {ref.k:g}, estimate {ref.estimate:.2e}, {ref.seconds:.0f} s",
              flush=True)
        runs: dict[str, list[dict]] = {"uniform": [], "adaptive": []}
        for r in range(args.rounds + 1):
            for mode in runs:
                rec = one(ref, cfg, args.tol, mode)
                print(f"  round {r} {mode}: P{rec['degree']} k={rec['k']:g} {rec['cells']} cells, error "
                      f"{rec['error']:.3e}, planning {rec['planning']:.2f} s, run {rec['loop']:.2f} s, "
                      f"{rec['steps']} steps ({rec['rejected']} rejected; {rec['compared']} levels compared)",
                      flush=True)
                if r > 0:
                    runs[mode].append(rec)

        def med(xs: list[float]) -> str:
            return f"{statistics.median(xs):.2f} ({min(xs):.2f}-{max(xs):.2f})"

        for mode, rs in runs.items():
            last = rs[-1]
            ratio = [a["cost"] / u["cost"] for a, u in zip(rs, runs["uniform"])]
            chosen = (f"P{last['degree']}, {last['cells']} cells, "
                      + (f"time.tolerance {last['time_part']:.2e} from k = {last['k']:.3g}" if mode == "adaptive"
                         else f"k = {last['k']:.3g}"))
            lines.append(f"| {name} | {mode} | {chosen} | {last['steps']} ({last['rejected']}) | {last['error']:.2e} | "
                         f"{last['error'] / args.tol:.2f} | "
                         f"{last['compared']} | {med([x['planning'] for x in rs])} | {med([x['loop'] for x in rs])} | "
                         f"{med([x['cost'] for x in rs])} | {med(ratio)} |")
        lines.append(f"| {name} | reference | {ref.cells} cells, k = {ref.k:.3g} | | (estimate {ref.estimate:.2e}) "
                     "| | | | | | |")
        del ref
        gc.collect()
    Path(args.output).write_text("\n".join(lines) + "\n")
    print("\n".join(lines))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
