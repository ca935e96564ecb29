"""The measurements behind ``solver.linear = "auto"`` (issue 30): PETSc's Cholesky, MUMPS and the iterative path.

    python scripts/auto_rule.py [--sizes2d 64 128 256] [--sizes3d 14 22] [--steps 20] [--repeats 3]
                                [--solvers petsc mumps iterative] [--out benchmarks/results]

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


def _case(dim: int, n: int, solver: str, steps: int, out: Path) -> dict:
    scene, k = SCENES[dim]
    sets = [f"mesh.nx={n}", f"mesh.ny={n}", *([f"mesh.nz={n}"] if dim == 3 else []), f"time.k={k}",
            f"time.T={steps * k!r}", f"solver.linear={solver}", "output.xdmf=false", "output.checkpoint_every=0"]
    cmd = [sys.executable, "-m", "solver", "run", scene, *(a for s in sets for a in ("--set", s)), "--no-progress",
           "--output", str(out)]
    t0 = time.perf_counter()
    res = subprocess.run(cmd, cwd=ROOT, capture_output=True, text=True)
    total = time.perf_counter() - t0
    if res.returncode != 0:
        return {"failed": (res.stderr.strip().splitlines() or ["?"])[-1][:200]}
    rows = list(csv.DictReader(open(out / "timeseries.csv")))
    step = [float(r["time_displacement"]) + float(r["time_damage"]) for r in rows[2:]]
    return {"total": total, "level0": float(rows[0]["wall_time"]),
            "level0_displacement": float(rows[0]["time_displacement"]), "step": statistics.median(step),
            "step_displacement": statistics.median(float(r["time_displacement"]) for r in rows[2:]),
            "step1_damage": float(rows[1]["time_damage"]),
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
    p.add_argument("--out", type=Path, default=ROOT / "benchmarks" / "results")
    args = p.parse_args(argv)
    sizes = [(2, n) for n in args.sizes2d] + [(3, n) for n in args.sizes3d]
    runs: dict[str, list[dict]] = {}
    with tempfile.TemporaryDirectory() as tmp:
        for r in range(args.repeats):
            for dim, n in sizes:
                for solver in args.solvers:
                    key = f"{dim}d n={n} {solver}"
                    runs.setdefault(key, []).append(_case(dim, n, solver, args.steps, Path(tmp) / f"{key}-{r}"))
                    print(key, r, {k: (round(v, 4) if isinstance(v, float) else v) for k, v in runs[key][-1].items()},
                          flush=True)
    med = {key: _median(rs) for key, rs in runs.items()}
    result = {"steps": args.steps, "repeats": args.repeats, "median": med, "runs": runs, "blas": dataclasses.asdict(blas.detect()),
              "date": time.strftime("%Y-%m-%d %H:%M UTC", time.gmtime())}
    args.out.mkdir(parents=True, exist_ok=True)
    (args.out / "auto_rule.json").write_text(json.dumps(result, indent=1) + "\n")
    (args.out / "auto_rule.md").write_text(_table(result, sizes, args.solvers))
    print(_table(result, sizes, args.solvers))
    return 0


def _dofs(dim: int, n: int) -> int:
    return dim * (n + 1) ** dim


def _table(r: dict, sizes: list[tuple[int, int]], solvers: list[str]) -> str:
    lines = [f"# solver.linear = auto: the measurements ({r['date']})", "",
             f"`python scripts/auto_rule.py` ({r['steps']} steps, {r['repeats']} repeats, one rank, medians; "
             "level 0 = the first factorizations or preconditioner set-ups; step = displacement + damage, median "
             "over steps 2..N).", "", blas.report_line(r["blas"]), "",
             "| case | dofs | solver | level 0 (s) | step (ms) | displacement / step (ms) | factorizations | "
             "contact force at T |", "|---|---|---|---|---|---|---|---|"]
    for dim, n in sizes:
        for solver in solvers:
            m = r["median"][f"{dim}d n={n} {solver}"]
            if "failed" in m:
                lines.append(f"| {dim}-D n = {n} | {_dofs(dim, n):,} | {solver} | failed: {m['failed']} | | | | |")
                continue
            lines.append(f"| {dim}-D n = {n} | {_dofs(dim, n):,} | {solver} | {m['level0']:.3g} | "
                         f"{1e3 * m['step']:.1f} | {1e3 * m['step_displacement']:.1f} | {m['factorizations']} | "
                         f"{m['contact_force']:.10g} |")
    lines += ["", "Break-even: after how many steps the solver with the dearer level 0 and the cheaper step "
              "catches up (level 0 difference / step difference; '-' where one is cheaper in both).", "",
              "| case | pair | break-even steps |", "|---|---|---|"]
    for dim, n in sizes:
        for i, a in enumerate(solvers):
            for b in solvers[i + 1:]:
                ma, mb = r["median"][f"{dim}d n={n} {a}"], r["median"][f"{dim}d n={n} {b}"]
                if "failed" in ma or "failed" in mb:
                    continue
                dl, ds = ma["level0"] - mb["level0"], ma["step"] - mb["step"]
                even = "-" if dl * ds >= 0 else f"{abs(dl / ds):.0f}"
                cheap = a if ma["step"] < mb["step"] else b
                lines.append(f"| {dim}-D n = {n} | {a} / {b} | {even} (cheaper steps: {cheap}) |")
    return "\n".join(lines) + "\n"


if __name__ == "__main__":
    sys.exit(main())
