"""The whole CLI run of Example 1 at n = 128, 200 steps: against a base tree, and split into its parts and floors.

    python scripts/run_floor.py compare [--base /work/base_fbee029] [--rounds 5] [--bytecode] [--name run_floor]
    python scripts/run_floor.py split [--tree .] [--repeats 3] [--name run_split]

``compare`` runs the whole command a user types, ``python -m solver run configs/example1.toml --set mesh.nx=128
--set mesh.ny=128 --set time.k=0.005 --no-progress`` (its default outputs: every level written, checkpoints),
from the base tree and from this one, alternated (base, this, base, this, ...), each a new process started in its
tree (so that tree's ``solver`` is imported), and reports per tree the median and range of the wall time and of
the CPU time (user + system of the process), the ratio of the medians and the median and range of the adjacent
pairs' ratios. ``--bytecode``: the children use Python's bytecode cache, as a user has it, each tree its own cache
under a temporary ``PYTHONPYCACHEPREFIX`` (filled by one untimed run of each tree first; the base tree is not
written to); without it, the environment's setting (PYTHONDONTWRITEBYTECODE=1 here: every run compiles the
project's modules).

``split`` runs the same command from ``--tree`` in a child that times its parts: the interpreter's start, the
imports, the model's set-up (build_model), the rest of the set-up (scene, directory, writers), level 0 and the
steps (their wall time less their output), the outputs (every level's ``time_output``), the rest of the run
(checkpoints, closing the files) and the end (report, MPI's finalize, exit). In the same child, after the run, the
floors of this tree's model (skipped for a tree whose objects are named otherwise): a step's triangular solve pair
on the displacement Jacobian, the damage solve, the damage and displacement right-hand sides; level 0's
factorization of J and of the damage matrix (a new KSP with the same options). And, in new processes, the
imports every dolfinx program pays (``from mpi4py import MPI; import dolfinx``).

Writes ``NAME.json`` and ``NAME.md`` under ``--out`` (benchmarks/results).
"""

from __future__ import annotations

import argparse
import csv
import json
import os
import resource
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
SCENE = "configs/example1.toml"
SETS = ["mesh.nx=128", "mesh.ny=128", "time.k=0.005"]


def _cpu() -> float:
    """User + system seconds of the finished child processes so far."""
    r = resource.getrusage(resource.RUSAGE_CHILDREN)
    return r.ru_utime + r.ru_stime


def _env(cache: Path | None) -> dict[str, str]:
    env = dict(os.environ)
    if cache is not None:
        env.pop("PYTHONDONTWRITEBYTECODE", None)
        env["PYTHONPYCACHEPREFIX"] = str(cache)
    return env


def _command(out: Path, sets: list[str]) -> list[str]:
    return [sys.executable, "-m", "solver", "run", SCENE, *(a for s in sets for a in ("--set", s)), "--no-progress",
            "--overwrite", "--output", str(out)]


def _waits() -> tuple[int, int, int]:
    """Voluntary context switches (waits: the disk, a sleep), involuntary ones (taken off the core by other work) and
    blocks written, of the finished child processes so far."""
    r = resource.getrusage(resource.RUSAGE_CHILDREN)
    return r.ru_nvcsw, r.ru_nivcsw, r.ru_oublock


def _whole(tree: Path, out: Path, sets: list[str], env: dict[str, str]) -> dict[str, float]:
    """One whole command from ``tree``: wall and CPU seconds, the time loop's (the CSV's wall_time summed), and its
    voluntary and involuntary context switches and blocks written."""
    t0, c0, w0 = time.perf_counter(), _cpu(), _waits()
    subprocess.run(_command(out, sets), cwd=tree, check=True, capture_output=True, env=env)
    wall, cpu, w1 = time.perf_counter() - t0, _cpu() - c0, _waits()
    rows = list(csv.DictReader(open(out / "timeseries.csv")))
    return {"wall": wall, "cpu": cpu, "loop": sum(float(r["wall_time"]) for r in rows),
            "voluntary_switches": w1[0] - w0[0], "involuntary_switches": w1[1] - w0[1], "blocks_written": w1[2] - w0[2]}


def _stats(values: list[float]) -> dict[str, float]:
    return {"median": statistics.median(values), "min": min(values), "max": max(values)}


def compare(args: argparse.Namespace) -> int:
    trees = {"base": args.base.resolve(), "this": ROOT}
    for tree in trees.values():
        probe = subprocess.run([sys.executable, "-c", "import solver; print(solver.__file__)"], cwd=tree,
                               check=True, capture_output=True, text=True, env=_env(None)).stdout.strip()
        if not probe.startswith(str(tree)):
            raise SystemExit(f"{tree}: imports {probe}, not its own solver")
    runs: dict[str, list[dict]] = {name: [] for name in trees}
    with tempfile.TemporaryDirectory() as tmp:
        tmp = Path(tmp)
        envs = {name: _env(tmp / f"pycache-{name}" if args.bytecode else None) for name in trees}
        if args.bytecode:
            for name, tree in trees.items():
                _whole(tree, tmp / f"warm-{name}", args.sets + (args.this_sets if name == "this" else []), envs[name])
        for i in range(args.rounds):
            for name, tree in trees.items():
                sets = args.sets + (args.this_sets if name == "this" else [])
                runs[name].append(_whole(tree, tmp / f"{name}{i}", sets, envs[name]))
                print(name, i, {k: round(v, 3) for k, v in runs[name][-1].items()}, os.getloadavg()[0], flush=True)
        rows_equal = _csv_equal(tmp / "base0" / "timeseries.csv", tmp / "this0" / "timeseries.csv")
    result = {"base": str(trees["base"]), "base_rev": _rev(trees["base"]), "this_rev": _rev(ROOT),
              "sets": args.sets, "this_sets": args.this_sets, "rounds": args.rounds, "bytecode": args.bytecode,
              "load": " ".join(f"{x:.1f}" for x in os.getloadavg()), "runs": runs, "csv": rows_equal,
              "stats": {name: {key: _stats([r[key] for r in rs]) for key in rs[0]} for name, rs in runs.items()},
              "pairs": {key: _stats([a[key] / max(b[key], 1e-300) for a, b in zip(runs["this"], runs["base"])])
                        for key in runs["this"][0]}}
    _write(args, result, _compare_table(result, args.name))
    return 0


def _rev(tree: Path) -> str:
    res = subprocess.run(["git", "describe", "--always", "--dirty"], cwd=tree, capture_output=True, text=True)
    return res.stdout.strip() or "?"


def _csv_equal(a: Path, b: Path) -> dict[str, float]:
    """The largest relative difference of each shared non-time column of two time series (0: equal)."""
    ra, rb = list(csv.DictReader(open(a))), list(csv.DictReader(open(b)))
    out = {}
    for col in ra[0]:
        if col.startswith("time_") or col == "wall_time" or col not in rb[0] or len(ra) != len(rb):
            continue
        x = [float(r[col]) for r in ra]
        y = [float(r[col]) for r in rb]
        scale = max(abs(v) for v in x) or 1.0
        out[col] = max(abs(p - q) for p, q in zip(x, y)) / scale
    return out


def _compare_table(r: dict, name: str) -> str:
    sets = " ".join(f"--set {s}" for s in r["sets"])
    s, p = r["stats"], r["pairs"]
    lines = [f"# The whole run of {SCENE} {sets} (one rank): this tree against {r['base_rev']}", "",
             f"`python scripts/run_floor.py compare --base {r['base']} --rounds {r['rounds']}"
             f"{''.join(f' --this-set {x}' for x in r.get('this_sets', []))}"
             f"{' --bytecode' if r['bytecode'] else ''} --name {name}`: this = {r['this_rev']}, base = "
             f"{r['base_rev']} (run from {r['base']}); {r['rounds']} rounds, alternated (base, this), each a new "
             f"process; Python's bytecode cache: {'used, one per tree' if r['bytecode'] else 'off (compiled at every run)'}; "
             f"load average at the end {r['load']} (2 cores, shared). Seconds: median [min, max].", "",
             "| | base | this | this / base (medians) | pairs' ratios: median [min, max] |", "|---|---|---|---|---|"]
    for label, key in (("whole command, wall", "wall"), ("whole command, CPU (user + system)", "cpu"),
                       ("time loop (the CSV's wall_time summed)", "loop"),
                       ("voluntary context switches (waits)", "voluntary_switches"),
                       ("involuntary context switches (other work)", "involuntary_switches"),
                       ("blocks written", "blocks_written")):
        if key not in s["base"]:
            continue
        b, a, q = s["base"][key], s["this"][key], p[key]
        fmt = ".2f" if key in ("wall", "cpu", "loop") else ".0f"
        lines.append(f"| {label} | {b['median']:{fmt}} [{b['min']:{fmt}}, {b['max']:{fmt}}] | {a['median']:{fmt}} "
                     f"[{a['min']:{fmt}}, {a['max']:{fmt}}] | {a['median'] / max(b['median'], 1e-300):.3f} | "
                     f"{q['median']:.3f} [{q['min']:.3f}, {q['max']:.3f}] |")
    worst = max(r["csv"].items(), key=lambda kv: kv[1]) if r["csv"] else ("-", 0.0)
    lines += ["", f"The time series of the first round, every shared column but the times: largest relative "
              f"difference {worst[1]:.1e} ({worst[0]}).", ""]
    return "\n".join(lines)


# the child of ``split``: the CLI run, its parts timed, then the floors of the model it built
CHILD = r"""
import json, sys, time
def now():
    return [time.time(), time.process_time()]
T = {"first_line": now()}
P = {}  # part -> [wall, cpu] summed
def timed(owner, name, key):
    inner = getattr(owner, name)
    def wrapper(*a, **k):
        w, c = time.perf_counter(), time.process_time()
        try:
            return inner(*a, **k)
        finally:
            part = key(a) if callable(key) else key
            acc = P.setdefault(part, [0.0, 0.0])
            acc[0] += time.perf_counter() - w; acc[1] += time.process_time() - c
    setattr(owner, name, wrapper)
import solver.run.model as _m
MODEL = []
_build = _m.build_model
def build_model(*a, **k):
    MODEL.append(_build(*a, **k)); return MODEL[-1]
_m.build_model = build_model
timed(_m, "build_model", "build_model")
import solver.cli, solver.io.results as _r, solver.run.stepper as _s, solver.io.checkpoint as _c
T["imported"] = now()
timed(_s.Stepper, "step", lambda a: "level 0" if a[1] == 0 else "steps")
timed(_r._Writers, "level", "outputs")
timed(_c, "write", "checkpoints")
timed(_r, "run", "run")
solver.cli.main(sys.argv[2:])
T["main_end"] = now()
T["parts"] = P
floors = {}
try:
    import floor_probe
    floors = floor_probe.floors(MODEL[-1])
except Exception as exc:  # another tree's objects: no floors
    floors = {"error": repr(exc)}
T["floors"] = floors
T["floors_done"] = now()
open(sys.argv[1], "w").write(json.dumps(T))
"""

# the floors, imported by the child from this script's folder (this tree's object names)
FLOORS = r"""
import time
import numpy as np
from petsc4py import PETSc

def _best(f, n=20):
    times = []
    for _ in range(n):
        t = time.process_time(); f(); times.append(time.process_time() - t)
    return float(np.min(times))  # a floor: the best of n, in CPU time (the machine is shared)

def _factor(A, options, n=3):
    best, ksp = float("inf"), None
    for _ in range(n):  # the best of n new factorizations (symbolic and numeric)
        ksp = PETSc.KSP().create(A.getComm())
        ksp.setOperators(A, A)
        ksp.setType(options.get("ksp_type", "preonly"))
        pc = ksp.getPC(); pc.setType(options["pc_type"]); pc.setFactorSolverType(options["pc_factor_mat_solver_type"])
        pc.setFactorOrdering(options["pc_factor_mat_ordering_type"])
        t = time.process_time(); ksp.setUp(); best = min(best, time.process_time() - t)
    return best, ksp

def floors(model):
    from solver.solvers.linear import direct_options
    mech, damage = model.mech, model.damage
    ksp = mech.solver.core.ksp
    b, x = mech.ops.b.duplicate(), mech.ops.b.duplicate()
    mech.ops.b.copy(b)
    out = {"displacement_solve": _best(lambda: ksp.solve(b, x))}
    out["damage_solve"] = _best(lambda: damage.ksp.solve(damage.b, damage.x))
    out["damage_rhs"] = _best(damage.assemble_rhs)
    t = model.cfg.time.T
    out["displacement_rhs"] = _best(lambda: mech.ops.assemble_rhs(t))
    opts = direct_options(model.comm, "petsc")
    J = mech.problem.J.copy()
    out["factor_J"], k1 = _factor(J, opts)
    out["solve_J_fresh"] = _best(lambda: k1.solve(b, x))
    out["factor_damage"], k2 = _factor(damage.A.copy(), opts)
    out["step_floor"] = (out["displacement_solve"] + out["damage_solve"] + out["damage_rhs"] + out["displacement_rhs"])
    # the same four one after the other, as a step does them (each finds the caches as the others left them)
    pieces = {"damage_rhs": damage.assemble_rhs, "damage_solve": lambda: damage.ksp.solve(damage.b, damage.x),
              "displacement_rhs": lambda: mech.ops.assemble_rhs(t), "displacement_solve": lambda: ksp.solve(b, x)}
    seq = {name: [] for name in pieces}
    for _ in range(20):
        for name, f in pieces.items():
            c = time.process_time(); f(); seq[name].append(time.process_time() - c)
    for name, times in seq.items():
        out["in_sequence_" + name] = float(np.median(times))
    out["step_in_sequence"] = sum(out["in_sequence_" + name] for name in pieces)
    out["dofs"] = mech.problem.J.getSize()[0]
    return out
"""


def split(args: argparse.Namespace) -> int:
    tree = args.tree.resolve()
    reps: list[dict] = []
    with tempfile.TemporaryDirectory() as tmp:
        tmp = Path(tmp)
        (tmp / "floor_probe.py").write_text(FLOORS)
        env = _env(tmp / "pycache" if args.bytecode else None)
        env["PYTHONPATH"] = str(tmp) + (os.pathsep + env["PYTHONPATH"] if env.get("PYTHONPATH") else "")
        for i in range(-1 if args.bytecode else 0, args.repeats):  # -1: the untimed run that fills the cache
            out, record = tmp / f"run{i}", tmp / f"times{i}.json"
            cmd = [sys.executable, "-c", CHILD, str(record), "run", SCENE, *(a for s in args.sets for a in ("--set", s)),
                   "--no-progress", "--overwrite", "--output", str(out)]
            start, c0 = time.time(), _cpu()
            subprocess.run(cmd, cwd=tree, check=True, capture_output=True, env=env)
            end, cpu = time.time(), _cpu() - c0
            T = json.loads(record.read_text())
            P = T["parts"]
            zero = [0.0, 0.0]
            inside = [P["run"][i] - sum(P.get(k, zero)[i] for k in ("level 0", "steps", "outputs", "checkpoints"))
                      for i in (0, 1)]
            main = [T["main_end"][i] - T["imported"][i] for i in (0, 1)]
            parts = {  # [wall, cpu]
                "interpreter and site": [T["first_line"][0] - start, T["first_line"][1]],
                "imports": [T["imported"][i] - T["first_line"][i] for i in (0, 1)],
                "build_model": P["build_model"],
                "other set-up (scene, directory, writers' opening) and the report":
                    [main[i] - P["run"][i] - P["build_model"][i] + inside[i] for i in (0, 1)],
                "level 0": P["level 0"], "steps": P["steps"], "outputs (every level)": P["outputs"],
                "checkpoints": P.get("checkpoints", zero),
            }
            rows = list(csv.DictReader(open(out / "timeseries.csv")))
            wall_total = end - start - (T["floors_done"][0] - T["main_end"][0])
            parts["exit (MPI finalize)"] = [end - T["floors_done"][0], cpu - T["floors_done"][1]]
            rep = {"total": wall_total, "cpu": cpu - (T["floors_done"][1] - T["main_end"][1]), "parts": parts,
                   "floors": T["floors"], "steps_n": len(rows) - 1}
            rep["imports_floor"] = _imports_floor(tree, env)
            if i < 0:
                continue
            reps.append(rep)
            print(i, json.dumps({k: [round(x, 3) for x in v] for k, v in parts.items()}), flush=True)
    result = {"tree": str(tree), "rev": _rev(tree), "sets": args.sets, "repeats": args.repeats, "bytecode": args.bytecode,
              "load": " ".join(f"{x:.1f}" for x in os.getloadavg()), "reps": reps}
    _write(args, result, _split_table(result, args.name))
    return 0


def _imports_floor(tree: Path, env: dict[str, str]) -> float:
    """CPU seconds of a process that imports what every dolfinx program imports."""
    c0 = _cpu()
    subprocess.run([sys.executable, "-c", "from mpi4py import MPI; import dolfinx, dolfinx.fem.petsc"], cwd=tree,
                   check=True, capture_output=True, env=env)
    return _cpu() - c0


SEQUENCE = ("in_sequence_displacement_solve", "in_sequence_damage_solve", "in_sequence_damage_rhs",
            "in_sequence_displacement_rhs")


def _split_table(r: dict, name: str) -> str:
    reps = r["reps"]
    med = {k: [statistics.median(rep["parts"][k][i] for rep in reps) for i in (0, 1)] for k in reps[0]["parts"]}
    total = [statistics.median(rep["total"] for rep in reps), statistics.median(rep["cpu"] for rep in reps)]
    sets = " ".join(f"--set {s}" for s in r["sets"])
    n = reps[0]["steps_n"]
    lines = [f"# The whole run of {SCENE} {sets} (one rank), split", "",
             f"`python scripts/run_floor.py split --tree {r['tree']} --repeats {r['repeats']}"
             f"{' --bytecode' if r['bytecode'] else ''} --name {name}` at {r['rev']}; Python's bytecode cache "
             f"{'used (its own, filled by an untimed run)' if r['bytecode'] else 'as the environment says'}; "
             f"{r['repeats']} runs, medians in seconds, wall and CPU (user + system of the process; "
             f"process_time inside it); load average at the end {r['load']} (2 cores, shared).", "",
             "| part | wall | CPU | share of the CPU |", "|---|---|---|---|"]
    lines += [f"| {k} | {w:.3f} | {c:.3f} | {c / total[1]:.0%} |" for k, (w, c) in med.items()]
    lines += [f"| whole process (the floors' time, measured after the run, left out) | {total[0]:.3f} | "
              f"{total[1]:.3f} | |", ""]
    fl = [rep["floors"] for rep in reps if "error" not in rep["floors"]]
    imp_floor = statistics.median(rep["imports_floor"] for rep in reps)
    exit_cpu = med["exit (MPI finalize)"][1]
    lines += [f"Start-up floor: a process that only does `from mpi4py import MPI; import dolfinx, dolfinx.fem.petsc` "
              f"(and exits) takes {imp_floor:.3f} s of CPU (median; the interpreter, MPI, dolfinx and the exit), against "
              f"{med['interpreter and site'][1] + med['imports'][1] + exit_cpu:.3f} s for the run's interpreter, "
              "imports and exit.", ""]
    if fl:
        f = {k: statistics.median(x[k] for x in fl) for k in fl[0] if isinstance(fl[0][k], float)}
        step = med["steps"][1] / n
        lines += [f"The floors of the model ({fl[0]['dofs']:,} displacement dofs), timed in the run's process after it "
                  "(CPU time, the best of 20 calls each, of 3 factorizations; ms):", "",
                  "| piece | ms |", "|---|---|",
                  f"| the displacement's triangular solve pair (the factored J) | {1e3 * f['displacement_solve']:.2f} |",
                  f"| the damage solve (its factored matrix) | {1e3 * f['damage_solve']:.2f} |",
                  f"| the damage right-hand side | {1e3 * f['damage_rhs']:.2f} |",
                  f"| the displacement right-hand side (loads, memory term) | {1e3 * f['displacement_rhs']:.2f} |",
                  f"| **a step's floor** (their sum) | **{1e3 * f['step_floor']:.2f}** |",
                  f"| the four one after the other, as a step does them (medians of 20 rounds): "
                  f"{', '.join(f'{1e3 * f[k]:.2f}' for k in SEQUENCE)}; "
                  f"sum | {1e3 * f['step_in_sequence']:.2f} |",
                  f"| a step of the run (CPU of the steps, output not counted, / {n}) | {1e3 * step:.2f} |",
                  f"| a level's output (CPU / {n + 1} levels) | {1e3 * med['outputs (every level)'][1] / (n + 1):.2f} |",
                  f"| level 0's floor: one Cholesky factorization of J (nd ordering) | {1e3 * f['factor_J']:.1f} |",
                  f"| the damage matrix's factorization | {1e3 * f['factor_damage']:.1f} |",
                  f"| level 0 of the run (CPU) | {1e3 * med['level 0'][1]:.1f} |", ""]
    else:
        lines += [f"No floors for this tree ({reps[0]['floors'].get('error')}).", ""]
    return "\n".join(lines)


def _write(args: argparse.Namespace, result: dict, text: str) -> None:
    args.out.mkdir(parents=True, exist_ok=True)
    (args.out / f"{args.name}.json").write_text(json.dumps(result, indent=1) + "\n")
    (args.out / f"{args.name}.md").write_text(text)
    print(text)


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    sub = p.add_subparsers(dest="what", required=True)
    c = sub.add_parser("compare", help="this tree against a base tree, alternated")
    c.add_argument("--base", type=Path, default=Path("/work/base_fbee029"))
    c.add_argument("--rounds", type=int, default=5)
    c.add_argument("--bytecode", action="store_true", help="a bytecode cache per tree (as a user has it)")
    c.add_argument("--name", default="run_floor")
    c.add_argument("--this-set", dest="this_sets", action="append", default=[], metavar="SECTION.KEY=VALUE",
                   help="overrides for this tree's runs only (e.g. another solver option against the base tree's default)")
    s = sub.add_parser("split", help="one tree's run split into its parts, and its floors")
    s.add_argument("--tree", type=Path, default=ROOT)
    s.add_argument("--repeats", type=int, default=3)
    s.add_argument("--name", default="run_split")
    s.add_argument("--bytecode", action="store_true", help="a bytecode cache of its own (as a user has it)")
    for q in (c, s):
        q.add_argument("--set", dest="sets", action="append", metavar="SECTION.KEY=VALUE",
                       help=f"scene overrides (default: {' '.join(SETS)})")
        q.add_argument("--out", type=Path, default=ROOT / "benchmarks" / "results")
    args = p.parse_args(argv)
    args.sets = args.sets or SETS
    return compare(args) if args.what == "compare" else split(args)


if __name__ == "__main__":
    sys.exit(main())
