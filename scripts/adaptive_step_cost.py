"""Where an adaptive run's time goes, beside the uniform run of equal error (time.adaptive; docs/model.md §3.9).

One scene at one tolerance: the adaptive run and the uniform run of (about) the same time error (``--uniform``
steps; the work-precision study, scripts/adaptive_work_precision.py, gives it), alternated ``--rounds`` times in
one process, each timed by parts: the stepper's memory, damage and displacement steps (rejected trials apart), the
damage matrix's re-assembly when k changes, Newton iterations and factorizations per level, and the controller's
own work (the estimate, the snapshot taken and restored). The parts are wrapped by timers (the same wrappers in
both runs). Times are the process's CPU seconds (time.process_time; ``--clock wall`` for wall-clock): on a shared,
loaded machine they move far less than wall-clock ones. Median over the rounds, range in brackets.

    python scripts/adaptive_step_cost.py [--scene hard] [--tolerance 3e-2] [--uniform 700] [--rounds 3]
        [--out benchmarks/results/adaptive_step_cost.md]
    python scripts/adaptive_step_cost.py --trees OLD_TREE . [...]   # two source trees side by side

``--trees``: this script (copied into each tree's scripts/) run by each tree in turn, one round each, alternated,
``--rounds`` times; the table gives each tree's adaptive/uniform time-loop ratio and its parts per level.
"""

from __future__ import annotations

import argparse
import json
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))  # this tree's solver, not an installed one

from mpi4py import MPI  # noqa: E402

import solver.run.adaptive as adaptive  # noqa: E402
import solver.run.scheme as scheme  # noqa: E402
from solver.config import load  # noqa: E402
from solver.run.model import build_model  # noqa: E402
from solver.run.stepper import Stepper, levels  # noqa: E402

SCENES = {"example1": "example1.toml", "hard": "hard.toml", "load_cycle": "load_cycle.toml"}
CLOCK = [time.process_time]
MESH = [8]  # cells across (--n)
MARKS = "output.times=[" + ", ".join(f"{i / 10:g}" for i in range(1, 10)) + "]"  # as the work-precision study


class Timers:
    """Seconds and calls per part, from wrappers put around methods."""

    def __init__(self) -> None:
        self.t: dict[str, float] = {}
        self.calls: dict[str, int] = {}

    def wrap(self, obj, name: str, label: str) -> None:
        inner = getattr(obj, name)

        def timed(*a, **kw):
            t0 = CLOCK[0]()
            try:
                return inner(*a, **kw)
            finally:
                self.t[label] = self.t.get(label, 0.0) + CLOCK[0]() - t0
                self.calls[label] = self.calls.get(label, 0) + 1

        setattr(obj, name, timed)


def one_run(scene: str, sets: list[str]) -> dict:
    cfg = load(ROOT / "configs" / SCENES[scene], [f"mesh.nx={MESH[0]}", f"mesh.ny={MESH[0]}", *sets])
    model = build_model(cfg, MPI.COMM_WORLD)
    timers = Timers()
    clock = adaptive.StepController(model) if cfg.time.adaptive else None
    if model.damage is not None:
        timers.wrap(model.damage, "_reassemble", "damage matrix (new k)")
    if clock is not None:
        timers.wrap(clock, "estimate", "estimate")
        timers.wrap(clock, "_accumulate", "estimate")
    counts = {"levels": -1, "trials": 0, "newton": 0, "factorizations": 0, "trial_newton": 0}
    stepper_t = Timers()
    originals = {}
    for cls in (scheme.FirstOrderScheme, scheme.SecondOrderScheme):
        for name in ("set_step", "memory", "damage", "displacement"):
            if name in vars(cls):
                originals[(cls, name)] = vars(cls)[name]
                stepper_t.wrap(cls, name, "memory" if name == "set_step" else name)
    originals[(Stepper, "step")] = Stepper.step
    stepper_t.wrap(Stepper, "step", "step")
    seen = []
    step = Stepper.step

    def step_seen(self, *a, **kw):
        before = dict(stepper_t.t)
        row = step(self, *a, **kw)
        seen.append((row, {k: v - before.get(k, 0.0) for k, v in stepper_t.t.items()}))
        return row

    Stepper.step = step_seen
    try:
        start = CLOCK[0]()
        accepted = []
        for row in levels(model, clock=clock):
            accepted.append(row)
        loop = CLOCK[0]() - start
    finally:
        for (cls, name), f in originals.items():
            setattr(cls, name, f)
    ids = {id(r) for r in accepted}
    parts = {"memory": 0.0, "damage": 0.0, "displacement": 0.0, "diagnostics": 0.0}
    trial_parts = dict(parts)
    for r, dt in seen[1:]:
        target = parts if id(r) in ids else trial_parts
        for p in ("memory", "damage", "displacement"):
            target[p] += dt.get(p, 0.0)
        target["diagnostics"] += dt.get("step", 0.0) - sum(dt.get(p, 0.0) for p in ("memory", "damage", "displacement"))
        if id(r) in ids:
            counts["newton"] += r["newton_iterations"]
            counts["factorizations"] += r["factorizations"]
        else:
            counts["trial_newton"] += r["newton_iterations"]
    counts["levels"] = len(accepted) - 1
    counts["trials"] = len(seen) - 1
    return {"loop": loop, "parts": parts, "trial_parts": trial_parts, "timers": dict(timers.t), "counts": counts,
            "changes": timers.calls.get("damage matrix (new k)", 0)}


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--scene", default="hard", choices=list(SCENES))
    p.add_argument("--tolerance", type=float, default=3e-2)
    p.add_argument("--uniform", type=int, default=700, help="steps of the uniform run of equal error")
    p.add_argument("--rounds", type=int, default=3)
    p.add_argument("--set", action="append", default=[], help="KEY=VALUE, an override for the adaptive run")
    p.add_argument("--clock", default="cpu", choices=["cpu", "wall"])
    p.add_argument("--n", type=int, default=8, help="cells across the mesh")
    p.add_argument("--out", default=str(ROOT / "benchmarks/results/adaptive_step_cost.md"))
    p.add_argument("--json", default="", help="write the runs' figures here instead of the table")
    p.add_argument("--trees", nargs=2, default=None, metavar=("A", "B"), help="two source trees, side by side")
    args = p.parse_args()
    CLOCK[0] = time.process_time if args.clock == "cpu" else time.perf_counter
    MESH[0] = args.n
    if args.trees:
        return trees(args)
    # the snapshot's methods are wrapped once, at the class (one Snapshot per run)
    snap_t = Timers()
    snap_t.wrap(adaptive.Snapshot, "take", "snapshot take")
    snap_t.wrap(adaptive.Snapshot, "restore", "snapshot restore")
    cases = {"adaptive": ["time.adaptive=true", f"time.tolerance={args.tolerance}", "time.k=0.01", MARKS, *args.set],
             "uniform": [f"time.k={1.0 / args.uniform}"]}
    runs: dict[str, list[dict]] = {c: [] for c in cases}
    for _ in range(args.rounds):
        for c, sets in cases.items():
            snap_t.t.clear()
            run = one_run(args.scene, sets)
            run["timers"].update(snap_t.t)
            runs[c].append(run)
            print(c, f"{run['loop']:.2f} s", run["counts"], flush=True)

    if args.json:
        Path(args.json).write_text(json.dumps({c: [{k: v for k, v in r.items()} for r in rs] for c, rs in runs.items()}))
        return

    def med(c: str, f) -> str:
        vals = [f(r) for r in runs[c]]
        return f"{statistics.median(vals):.3f} [{min(vals):.3f}, {max(vals):.3f}]"

    def both(label: str, f) -> str:
        return f"| {label} | {med('adaptive', f)} | {med('uniform', f)} |"

    a0, u0 = runs["adaptive"][0], runs["uniform"][0]
    lines = [f"# Where an adaptive run's time goes: {args.scene}, {args.n} x {args.n}, order 1", "",
             f"`python scripts/adaptive_step_cost.py --scene {args.scene} --tolerance {args.tolerance:g} "
             f"--uniform {args.uniform} --rounds {args.rounds} --clock {args.clock} --n {args.n}"
             f"{''.join(' --set ' + s for s in args.set)}`", "",
             f"Adaptive at tolerance {args.tolerance:g} ({a0['counts']['levels']} levels, "
             f"{a0['counts']['trials'] - a0['counts']['levels']} rejected trials, {a0['changes']} changes of k) "
             f"against {args.uniform} uniform steps. {args.clock.upper()} seconds, "
             f"median [range] over {args.rounds} rounds, alternated.",
             "", "| part | adaptive | uniform |", "|---|---|---|",
             both("time loop", lambda r: r["loop"])]
    for p_ in ("memory", "damage", "displacement", "diagnostics"):
        label = f"accepted levels: {p_}" + (" (and the row)" if p_ == "diagnostics" else "")
        lines.append(both(label, lambda r, p_=p_: r["parts"][p_]))
    lines.append(both("rejected trials (all parts)", lambda r: sum(r["trial_parts"].values())))
    for t in ("damage matrix (new k)", "estimate", "snapshot take", "snapshot restore"):
        lines.append(both(f"{t} (within the above)" if t.startswith("damage") else t,
                          lambda r, t=t: r["timers"].get(t, 0.0)))
    lines.append(both("rest of the loop (controller, generator)",
                      lambda r: r["loop"] - sum(r["parts"].values()) - sum(r["trial_parts"].values())
                      - sum(v for k, v in r["timers"].items() if not k.startswith("damage"))))
    lines.append(both("per level (loop / levels)", lambda r: r["loop"] / r["counts"]["levels"]))
    lines += ["", "| count | adaptive | uniform |", "|---|---|---|"]
    for key in ("levels", "trials", "newton", "factorizations", "trial_newton"):
        lines.append(f"| {key} | {a0['counts'][key]} | {u0['counts'][key]} |")
    lines.append(f"| Newton iterations per accepted level | {a0['counts']['newton'] / a0['counts']['levels']:.2f} | "
                 f"{u0['counts']['newton'] / u0['counts']['levels']:.2f} |")
    lines.append(f"| changes of k | {a0['changes']} | {u0['changes']} |")
    text = "\n".join(lines) + "\n"
    Path(args.out).write_text(text)
    print(text)


def trees(args: argparse.Namespace) -> None:
    """Each tree's copy of this script, one round each, alternated; per tree the adaptive/uniform loop ratio and the
    adaptive run's overhead per level (estimate, snapshot) over the uniform run's time per level."""
    got: dict[str, list[dict]] = {t: [] for t in args.trees}
    with tempfile.TemporaryDirectory() as tmp:
        for _ in range(args.rounds):
            for t in args.trees:
                out = Path(tmp) / "run.json"
                cmd = [sys.executable, str(Path(t) / "scripts" / "adaptive_step_cost.py"), "--scene", args.scene,
                       "--tolerance", str(args.tolerance), "--uniform", str(args.uniform), "--rounds", "1",
                       "--clock", args.clock, "--n", str(args.n), "--json", str(out), *[x for s in args.set for x in ("--set", s)]]
                subprocess.run(cmd, check=True, cwd=t, capture_output=True)
                data = json.loads(out.read_text())
                a, u = data["adaptive"][0], data["uniform"][0]
                per_u = u["loop"] / u["counts"]["levels"]
                got[t].append({"ratio": a["loop"] / u["loop"], "per_level": (a["loop"] / a["counts"]["levels"]) / per_u,
                               "estimate": a["timers"].get("estimate", 0.0) / a["counts"]["levels"] / per_u,
                               "snapshot": a["timers"].get("snapshot take", 0.0) / a["counts"]["levels"] / per_u,
                               "levels": a["counts"]["levels"], "trials": a["counts"]["trials"]})
                print(t, got[t][-1], flush=True)

    def med(vals: list[float]) -> str:
        return f"{statistics.median(vals):.3f} [{min(vals):.3f}, {max(vals):.3f}]"

    lines = [f"# Adaptive against uniform, two trees side by side: {args.scene}, {args.n} x {args.n}, order 1", "",
             f"`python scripts/adaptive_step_cost.py --trees {' '.join(args.trees)} --scene {args.scene} "
             f"--tolerance {args.tolerance:g} --uniform {args.uniform} --rounds {args.rounds} --clock {args.clock} "
             f"--n {args.n}`", "",
             f"Adaptive at tolerance {args.tolerance:g} against {args.uniform} uniform steps, each tree's run in "
             f"turn, {args.rounds} rounds; {args.clock} seconds. Median [range]; per level: over the uniform run's "
             "time per level.", "",
             "| tree | levels (trials) | adaptive / uniform time loop | time per level | estimate per level | "
             "snapshot per level |", "|---|---|---|---|---|---|"]
    for t, rs in got.items():
        lines.append(f"| {t} | {rs[0]['levels']} ({rs[0]['trials']}) | {med([r['ratio'] for r in rs])} | "
                     f"{med([r['per_level'] for r in rs])} | {med([r['estimate'] for r in rs])} | "
                     f"{med([r['snapshot'] for r in rs])} |")
    text = "\n".join(lines) + "\n"
    Path(args.out).write_text(text)
    print(text)


if __name__ == "__main__":
    main()
