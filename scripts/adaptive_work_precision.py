"""Work-precision of adaptive steps against uniform steps (time.adaptive; docs/model.md §3.9).

For each scene: a fine uniform reference (``--ref`` steps), uniform runs with N = 10·2^j steps and adaptive runs at a
range of ``time.tolerance``, each measured by its levels (and the adaptive run's rejected trials), its time loop
and its time error against the reference in the paper's norm (the time loop in the process's CPU seconds by
default: on a shared machine wall-clock seconds of one run moved by 2-5x between rounds), max over t = 0.1, 0.2, ..., 1 of
||eps(u - u_ref)|| + ||zeta - zeta_ref|| (same mesh: time error only; the adaptive runs land on these times).
Every run is repeated ``--rounds`` times,
the cases alternated within a round, and the median time kept. The uniform run that reaches an adaptive run's
error is interpolated log-log between the two uniform runs around it.

    python scripts/adaptive_work_precision.py [--scenes example1 hard load_cycle] [--rounds 3]
        [--ref 10240] [--tolerances 1e-2 1e-3 ...] [--set KEY=VALUE ...]
        [--out benchmarks/results/NAME] [--chart PATH or '']

(``--tolerances``: the same for every scene, instead of each scene's own; ``--set``: a scene override for every
run, e.g. another contact compliance).

writes benchmarks/results/adaptive_work_precision.{json,md} and docs/figures/adaptive_work_precision.png.
"""

from __future__ import annotations

import argparse
import json
import math
import statistics
import sys
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))  # this tree's solver, not an installed one

import dolfinx.fem.petsc  # noqa: E402, F401
import ufl  # noqa: E402
from dolfinx import fem  # noqa: E402
from mpi4py import MPI  # noqa: E402

from solver.config import load  # noqa: E402
from solver.run.adaptive import StepController  # noqa: E402
from solver.run.model import build_model  # noqa: E402
from solver.run.stepper import levels  # noqa: E402

SCENES = {
    "example1": ("example1.toml", ["mesh.nx=8", "mesh.ny=8"]),
    "hard": ("hard.toml", ["mesh.nx=8", "mesh.ny=8"]),
    "load_cycle": ("load_cycle.toml", ["mesh.nx=8", "mesh.ny=8"]),
}
UNIFORM = [10, 20, 40, 80, 160, 320, 640, 1280, 2560]
CHECK = [i / 10 for i in range(1, 11)]  # the error is the largest at these times (every run has a level there)
# per scene, tolerances whose runs land inside the uniform runs' error range (the estimate is conservative: the
# achieved error is 1/5 to 1/40 of the tolerance, more on Example 1)
TOLERANCES = {"example1": [1e-2, 1e-3, 3e-4], "hard": [1e-1, 3e-2, 1e-2], "load_cycle": [1e-1, 3e-2, 1e-2]}


EXTRA: list[str] = []  # --set: overrides for every run
CLOCK = [time.process_time]  # --clock: the process's CPU seconds (a loaded machine moves them far less) or wall


def one_run(scene: str, sets: list[str]) -> dict:
    """A run in memory: its final u and zeta, levels, rejected trials and the time loop in seconds."""
    file, base = SCENES[scene]
    cfg = load(ROOT / "configs" / file, [*base, *EXTRA, *sets])
    model = build_model(cfg, MPI.COMM_WORLD)
    clock = StepController(model) if cfg.time.adaptive else None  # set-up (its forms), as build_model: not timed
    at, rows, loop = {}, [], 0.0
    now = CLOCK[0]
    start = now()
    for row in levels(model, clock=clock):
        rows.append(row)
        near = [c for c in CHECK if abs(row["t"] - c) <= 1e-9]
        if near:  # a copy for the error, its time not counted
            loop += now() - start
            z = model.damage.zeta.x.array.copy() if model.damage is not None else None
            at[near[0]] = (model.u.x.array.copy(), z)
            start = now()
    loop += now() - start
    return {"model": model, "at": at, "levels": len(rows) - 1,
            "rejected": sum(int(r.get("rejected", 0)) for r in rows), "loop": loop, "t": rows[-1]["t"]}


def error(ref: dict, run: dict) -> float:
    """max over CHECK of ||eps(u - u_ref)|| + ||zeta - zeta_ref|| (the paper's norm is a max over the levels)."""
    model = ref["model"]
    du = fem.Function(model.u.function_space)
    e = ufl.sym(ufl.grad(du))
    fu = fem.form(ufl.inner(e, e) * ufl.dx)
    dz = fem.Function(model.damage.V) if model.damage is not None else None
    fz = fem.form(dz * dz * ufl.dx) if dz is not None else None
    worst = 0.0
    for c in CHECK:
        (u, z), (u_ref, z_ref) = run["at"][c], ref["at"][c]
        du.x.array[:] = u - u_ref
        out = math.sqrt(MPI.COMM_WORLD.allreduce(fem.assemble_scalar(fu), op=MPI.SUM))
        if dz is not None:
            dz.x.array[:] = z - z_ref
            out += math.sqrt(MPI.COMM_WORLD.allreduce(fem.assemble_scalar(fz), op=MPI.SUM))
        worst = max(worst, out)
    return worst


def uniform_at(err: float, uniform: list[dict], key: str) -> float:
    """The uniform runs' ``key`` (levels or loop time) at error ``err``, log-log between the two around it (NaN
    outside their range)."""
    pts = sorted((u["error"], u[key]) for u in uniform if u["error"] > 0)
    for (e0, v0), (e1, v1) in zip(pts, pts[1:]):
        if e0 <= err <= e1:
            s = (math.log(err) - math.log(e0)) / (math.log(e1) - math.log(e0))
            return math.exp(math.log(v0) + s * (math.log(v1) - math.log(v0)))
    return math.nan


def study(scene: str, rounds: int, ref_steps: int) -> dict:
    ref = one_run(scene, [f"time.k={1.0 / ref_steps}"])
    cases = [("uniform", n, [f"time.k={1.0 / n}"]) for n in UNIFORM if 4 * n <= ref_steps]  # ref at least 4x finer
    marks = "output.times=[" + ", ".join(f"{c:g}" for c in CHECK[:-1]) + "]"  # adaptive steps land there
    cases += [("adaptive", tol, ["time.adaptive=true", f"time.tolerance={tol}", "time.k=0.01", marks])
              for tol in TOLERANCES[scene]]
    times: dict[int, list[float]] = {i: [] for i in range(len(cases))}
    results: dict[int, dict] = {}
    for _ in range(rounds):
        for i, (_, _, sets) in enumerate(cases):
            run = one_run(scene, sets)
            times[i].append(run["loop"])
            results[i] = {"levels": run["levels"], "rejected": run["rejected"], "error": error(ref, run)}
    out = {"uniform": [], "adaptive": []}
    for i, (kind, value, _) in enumerate(cases):
        row = {"steps" if kind == "uniform" else "tolerance": value, **results[i],
               "loop": statistics.median(times[i]), "loop_range": [min(times[i]), max(times[i])]}
        out[kind].append(row)
    for a in out["adaptive"]:
        a["trials"] = a["levels"] + a["rejected"]
        a["uniform_levels"] = uniform_at(a["error"], out["uniform"], "levels")
        a["uniform_loop"] = uniform_at(a["error"], out["uniform"], "loop")
        a["steps_ratio"] = a["trials"] / a["uniform_levels"]
        a["time_ratio"] = a["loop"] / a["uniform_loop"]
        a["reliable"] = a["error"] <= a["tolerance"]
        a["failures"] = failures(a)
    return out


def failures(a: dict) -> list[str]:
    """Where adaptivity fails on a case: unreliable, more steps or time than the uniform run at its error, or the
    targets (steps <= 1/2, time <= 2/3) missed; empty when it meets them."""
    out = []
    if not a["reliable"]:
        out.append("error above the tolerance")
    if not math.isfinite(a["steps_ratio"]):
        out.append("error outside the uniform runs' range")
    elif a["steps_ratio"] > 1:
        out.append("more steps than uniform")
    elif a["steps_ratio"] > 0.5:
        out.append("steps > 1/2 uniform")
    if math.isfinite(a["time_ratio"]) and a["time_ratio"] > 1:
        out.append("more time than uniform")
    elif math.isfinite(a["time_ratio"]) and a["time_ratio"] > 2 / 3:
        out.append("time > 2/3 uniform")
    return out


def chart(data: dict, path: Path) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, axes = plt.subplots(2, len(data), figsize=(4.6 * len(data), 8.0), squeeze=False)
    for j, (scene, d) in enumerate(data.items()):
        for i, key in enumerate(("levels", "loop")):
            ax = axes[i][j]
            u = d["uniform"]
            ax.loglog([r["error"] for r in u], [r[key] for r in u], "o-", color="C0", label="uniform")
            target = 0.5 if key == "levels" else 2 / 3
            ax.loglog([r["error"] for r in u], [target * r[key] for r in u], "--", color="C0", lw=0.8, alpha=0.6,
                      label=f"target: {'1/2' if key == 'levels' else '2/3'} of uniform")
            a = d["adaptive"]
            ys = [r["trials" if key == "levels" else key] for r in a]
            ax.loglog([r["error"] for r in a], ys, "s-", color="C3", label="adaptive (achieved error)")
            for n, (r, y) in enumerate(zip(a, ys)):  # each run's tolerance at its height: error <= tolerance
                ax.plot([r["error"], r["tolerance"]], [y, y], ":", color="C3", lw=1.0)
                ax.plot([r["tolerance"]], [y], "|", color="C3", ms=12, mew=2,
                        label="its tolerance" if n == 0 else None)
                ax.annotate(f"tol {r['tolerance']:g}", (r["tolerance"], y), textcoords="offset points",
                            xytext=(-4, 6), ha="right", fontsize=7, color="C3")
            ax.set_xlabel("time error, max over t = 0.1..1 (paper's norm)")
            unit = "CPU s" if CLOCK[0] is time.process_time else "s"
            ax.set_ylabel("steps (adaptive: accepted + rejected)" if key == "levels" else f"time loop [{unit}]")
            ax.set_title(scene)
            ax.grid(True, which="both", alpha=0.3)
            ax.legend(fontsize=7, loc="lower left")
    fig.suptitle("Adaptive vs uniform steps (8 x 8, order 1)\na dotted line joins each adaptive run's error to "
                 "its tolerance", fontsize=10)
    fig.tight_layout()
    fig.savefig(path, dpi=110)


def command(args: argparse.Namespace, scenes: list[str]) -> str:
    tols = f" --tolerances {' '.join(f'{t:g}' for t in args.tolerances)}" if args.tolerances else ""
    sets = "".join(f" --set {x}" for x in args.set)
    return (f"python scripts/adaptive_work_precision.py --scenes {' '.join(scenes)} --rounds {args.rounds} "
            f"--ref {args.ref}{tols}{sets} --clock {args.clock}")


def markdown(data: dict, args: argparse.Namespace) -> str:
    lines = ["# Adaptive steps: work-precision", "",
             "8 x 8 meshes, order 1; error: max over t = 0.1, ..., 1 of the paper's norm against a fine uniform "
             "reference (each scene's command gives its reference steps, rounds and clock; the time loop, in CPU seconds with --clock "
             "cpu, is the median over "
             "the rounds, the cases alternated within a round). "
             "Ratios: the adaptive run's steps (accepted + rejected) and time loop over the uniform run's that "
             "reaches the same error (interpolated log-log; NaN: outside the uniform runs' range). Target: steps "
             "<= 0.5, time <= 0.67, error <= tolerance.", ""]
    for scene, d in data.items():
        lines += [f"## {scene}", "", f"`{d.get('command', command(args, [scene]))}`", "",
                  "| tolerance | levels | rejected | error | reliable | steps ratio | time ratio |",
                  "|---|---|---|---|---|---|---|"]
        for a in d["adaptive"]:
            lines.append(f"| {a['tolerance']:g} | {a['levels']} | {a['rejected']} | {a['error']:.3g} | "
                         f"{'yes' if a['reliable'] else 'NO'} | {a['steps_ratio']:.2f} | {a['time_ratio']:.2f} |")
        lines += ["", "| uniform steps | error | time loop [s] |", "|---|---|---|"]
        for u in d["uniform"]:
            lines.append(f"| {u['steps']} | {u['error']:.3g} | {u['loop']:.2f} |")
        lines.append("")
    lines += ["## Where adaptivity fails", "", "| scene | tolerance | steps ratio | time ratio | failure |", "|---|---|---|---|---|"]
    for scene, d in data.items():
        for a in d["adaptive"]:
            lines.append(f"| {scene} | {a['tolerance']:g} | {a['steps_ratio']:.2f} | {a['time_ratio']:.2f} | "
                         f"{'; '.join(a['failures']) or 'none (targets met)'} |")
    lines.append("")
    return "\n".join(lines)


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--scenes", nargs="+", default=list(SCENES), choices=list(SCENES))
    p.add_argument("--rounds", type=int, default=3)
    p.add_argument("--ref", type=int, default=10240)
    p.add_argument("--tolerances", type=float, nargs="+", default=None)
    p.add_argument("--set", action="append", default=[], help="KEY=VALUE, an override for every run")
    p.add_argument("--out", default=str(ROOT / "benchmarks/results/adaptive_work_precision"))
    p.add_argument("--redraw", action="store_true", help="only draw the chart (and the .md) from the --out .json")
    p.add_argument("--append", action="store_true", help="keep the other scenes of the existing --out .json")
    p.add_argument("--clock", default="cpu", choices=["cpu", "wall"],
                   help="time loops in CPU seconds of the process (default) or wall-clock seconds")
    p.add_argument("--chart", default=str(ROOT / "docs/figures/adaptive_work_precision.png"), help="'' for none")
    args = p.parse_args()
    if args.tolerances:
        for scene in TOLERANCES:
            TOLERANCES[scene] = args.tolerances
    EXTRA[:] = args.set
    CLOCK[0] = time.process_time if args.clock == "cpu" else time.perf_counter
    data, out = {}, Path(args.out)
    if args.redraw:
        data = json.loads(out.with_suffix(".json").read_text())
        out.with_suffix(".md").write_text(markdown(data, args))
        chart(data, Path(args.chart))
        return
    if args.append and out.with_suffix(".json").exists():
        data = {k: v for k, v in json.loads(out.with_suffix(".json").read_text()).items() if k not in args.scenes}
    for scene in args.scenes:  # written after each scene: a study cut short keeps the scenes it finished
        data[scene] = study(scene, args.rounds, args.ref)
        data[scene]["command"] = command(args, [scene])
        out.with_suffix(".json").write_text(json.dumps(data, indent=1, default=float) + "\n")
        out.with_suffix(".md").write_text(markdown(data, args))
        if args.chart:
            chart(data, Path(args.chart))
        print(markdown({scene: data[scene]}, args), flush=True)


if __name__ == "__main__":
    main()
