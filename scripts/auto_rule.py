"""The measurements behind ``solver.linear = "auto"`` (issue 30): PETSc's Cholesky, MUMPS and the iterative path.

    python scripts/auto_rule.py [--sizes2d 64 128 256] [--sizes3d 14 22] [--steps 20] [--repeats 3]
                                [--solvers petsc mumps iterative] [--solvers3d mumps iterative] [--out DIR]

Each case is one CLI run in its own process, one rank: Example 1 (configs/example1.toml, k = 0.01) at n x n and
the 3-D Example 1 (configs/example1_3d.toml, k = 0.02) at n x n x n, ``--steps`` steps, with
``solver.linear`` set to each solver in turn; no fields or checkpoints written (``output.xdmf = false``,
``output.checkpoint_every = 0``). The solvers of one size run one after the other, and the repeats go round all
sizes again, so that the machine's load falls on all of them alike (the ratios are what is read). From each
run's timeseries.csv: level 0 (the first factorizations or preconditioner set-ups: K, then K + C), the time of a
step (displacement + damage, median over the steps after step 1, whose damage solve factors its matrix), the
factorizations. Reported per case: medians over the repeats; per size: the number of steps after which a
solver's cheaper steps repay its dearer level 0 (break-even). Writes ``auto_rule.json`` and ``auto_rule.md``.
"""

from __future__ import annotations

import argparse
import csv
import dataclasses
import json
import resource
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))
from studies import blas  # noqa: E402  (the BLAS the runs load: the same interpreter's)

SCENES = {2: ("configs/example1.toml", 0.01), 3: ("configs/example1_3d.toml", 0.02)}
SHORT = 2  # steps of the short run


def _run(dim: int, n: int, solver: str, steps: int, out: Path) -> tuple[float, float, list[dict] | str]:
    """One CLI run: its wall time, its CPU time (user + system, of the process and its children), its CSV rows."""
    scene, k = SCENES[dim]
    sets = [f"mesh.nx={n}", f"mesh.ny={n}", *([f"mesh.nz={n}"] if dim == 3 else []), f"time.k={k}",
            f"time.T={steps * k!r}", f"solver.linear={solver}", "output.xdmf=false", "output.checkpoint_every=0"]
    cmd = [sys.executable, "-m", "solver", "run", scene, *(a for s in sets for a in ("--set", s)), "--no-progress",
           "--output", str(out)]
    before = resource.getrusage(resource.RUSAGE_CHILDREN)
    t0 = time.perf_counter()
    res = subprocess.run(cmd, cwd=ROOT, capture_output=True, text=True)
    wall = time.perf_counter() - t0
    after = resource.getrusage(resource.RUSAGE_CHILDREN)
    cpu = (after.ru_utime - before.ru_utime) + (after.ru_stime - before.ru_stime)
    if res.returncode != 0:
        return wall, cpu, (res.stderr.strip().splitlines() or ["?"])[-1][:200]
    return wall, cpu, list(csv.DictReader(open(out / "timeseries.csv")))


def _case(dim: int, n: int, solver: str, steps: int, out: Path) -> dict:
    """A short run (SHORT steps) and a long one (SHORT + ``steps``): the CPU time of a step is their difference over
    ``steps``, and the fixed CPU time (start-up, level 0, the end) what the short run spent besides its steps. CPU
    time, unlike wall time, does not count the waits for a core the machine's other work causes."""
    _, cpu_short, short = _run(dim, n, solver, SHORT, out / "short")
    wall, cpu_long, rows = _run(dim, n, solver, SHORT + steps, out / "long")
    if isinstance(rows, str) or isinstance(short, str):
        return {"failed": rows if isinstance(rows, str) else short}
    step = [float(r["time_displacement"]) + float(r["time_damage"]) for r in rows[2:]]
    cpu_step = (cpu_long - cpu_short) / steps
    return {"total": wall, "level0": float(rows[0]["wall_time"]),
            "level0_displacement": float(rows[0]["time_displacement"]), "step": statistics.median(step),
            "step_displacement": statistics.median(float(r["time_displacement"]) for r in rows[2:]),
            "step1_damage": float(rows[1]["time_damage"]), "cpu_step": cpu_step,
            "cpu_fixed": cpu_short - SHORT * cpu_step, "cpu_run": cpu_long,
            "factorizations": sum(int(r["factorizations"]) for r in rows),
            "contact_force": float(rows[-1]["contact_force"])}


def _median(runs: list[dict]) -> dict:
    ok = [r for r in runs if "failed" not in r]
    if not ok:
        return runs[0]
    return {key: (statistics.median(r[key] for r in ok) if isinstance(ok[0][key], float) else ok[0][key])
            for key in ok[0]}


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--sizes2d", type=int, nargs="*", default=[64, 128, 256])
    p.add_argument("--sizes3d", type=int, nargs="*", default=[14, 22])
    p.add_argument("--steps", type=int, default=20)
    p.add_argument("--repeats", type=int, default=3)
    p.add_argument("--solvers", nargs="+", default=["petsc", "mumps", "iterative"])
    p.add_argument("--solvers3d", nargs="+", default=["mumps", "iterative"],
                   help="in 3-D (PETSc's Cholesky fills too much: level 0 took 11 s against MUMPS's 1.5 s at 10,125 dofs)")
    p.add_argument("--out", type=Path, default=ROOT / "benchmarks" / "results")
    p.add_argument("--render", action="store_true", help="write auto_rule.md again from --out's auto_rule.json")
    args = p.parse_args(argv)
    sizes = [(2, n) for n in args.sizes2d] + [(3, n) for n in args.sizes3d]
    if args.render:
        result = json.loads((args.out / "auto_rule.json").read_text())
        sizes = [tuple(s) for s in result["sizes"]]
        table = _table(result, sizes, {int(k): v for k, v in result["solvers"].items()})
        (args.out / "auto_rule.md").write_text(table)
        print(table)
        return 0
    runs: dict[str, list[dict]] = {}
    with tempfile.TemporaryDirectory() as tmp:
        for r in range(args.repeats):
            for dim, n in sizes:
                for solver in (args.solvers if dim == 2 else args.solvers3d):
                    key = f"{dim}d n={n} {solver}"
                    runs.setdefault(key, []).append(_case(dim, n, solver, args.steps, Path(tmp) / f"{key}-{r}"))
                    print(key, r, {k: (round(v, 4) if isinstance(v, float) else v) for k, v in runs[key][-1].items()},
                          flush=True)
    med = {key: _median(rs) for key, rs in runs.items()}
    result = {"steps": args.steps, "repeats": args.repeats, "median": med, "runs": runs, "sizes": sizes,
              "solvers": {2: args.solvers, 3: args.solvers3d}, "blas": dataclasses.asdict(blas.detect()),
              "date": time.strftime("%Y-%m-%d %H:%M UTC", time.gmtime())}
    args.out.mkdir(parents=True, exist_ok=True)
    (args.out / "auto_rule.json").write_text(json.dumps(result, indent=1) + "\n")
    table = _table(result, sizes, {2: args.solvers, 3: args.solvers3d})
    (args.out / "auto_rule.md").write_text(table)
    print(table)
    return 0


def _dofs(dim: int, n: int) -> int:
    return dim * (n + 1) ** dim


def _even(ma: dict, mb: dict, fixed: str, step: str, a: str, b: str) -> str:
    dl, ds = ma[fixed] - mb[fixed], ma[step] - mb[step]
    cheap = a if ma[step] < mb[step] else b
    return f"- ({cheap} cheaper in both)" if dl * ds >= 0 else f"{abs(dl / ds):.0f} (cheaper steps: {cheap})"


def _table(r: dict, sizes: list[tuple[int, int]], solvers_of: dict[int, list[str]]) -> str:
    lines = [f"# solver.linear = auto: the measurements ({r['date']})", "",
             f"`python scripts/auto_rule.py` ({r['steps']} steps, {r['repeats']} repeats, one rank, medians; "
             "level 0 = the first factorizations or preconditioner set-ups; step = displacement + damage, median "
             "over steps 2..N).", "", blas.report_line(r["blas"]), "",
             "| case | dofs | solver | level 0 (s) | step (ms) | displacement / step (ms) | CPU fixed (s) | "
             "CPU / step (ms) | CPU of the run (s) | factorizations | contact force at T |",
             "|---|---|---|---|---|---|---|---|---|---|---|"]
    for dim, n in sizes:
        for solver in solvers_of[dim]:
            m = r["median"][f"{dim}d n={n} {solver}"]
            if "failed" in m:
                lines.append(f"| {dim}-D n = {n} | {_dofs(dim, n):,} | {solver} | failed: {m['failed']} "
                             "| | | | | | | |")
                continue
            lines.append(f"| {dim}-D n = {n} | {_dofs(dim, n):,} | {solver} | {m['level0']:.3g} | "
                         f"{1e3 * m['step']:.1f} | {1e3 * m['step_displacement']:.1f} | {m['cpu_fixed']:.3g} | "
                         f"{1e3 * m['cpu_step']:.1f} | {m['cpu_run']:.3g} | {m['factorizations']} | "
                         f"{m['contact_force']:.10g} |")
    lines += ["", "Break-even: after how many steps the solver with the dearer level 0 and the cheaper step "
              "catches up (level 0 difference / step difference; '-' where one is cheaper in both), from the wall "
              "times and from the CPU times (fixed and per step).", "",
              "| case | pair | break-even steps (wall) | break-even steps (CPU) |", "|---|---|---|---|"]
    for dim, n in sizes:
        solvers = solvers_of[dim]
        for i, a in enumerate(solvers):
            for b in solvers[i + 1:]:
                ma, mb = r["median"][f"{dim}d n={n} {a}"], r["median"][f"{dim}d n={n} {b}"]
                if "failed" in ma or "failed" in mb:
                    continue
                lines.append(f"| {dim}-D n = {n} | {a} / {b} | {_even(ma, mb, 'level0', 'step', a, b)} | "
                             f"{_even(ma, mb, 'cpu_fixed', 'cpu_step', a, b)} |")
    return "\n".join(lines) + "\n"


if __name__ == "__main__":
    sys.exit(main())
