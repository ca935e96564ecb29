"""Start-up of the whole CLI run of Example 1 (issue 30): this checkout against an earlier commit, alternated.

    python scripts/startup.py [--before REV] [--repeats 5] [--scene configs/example1.toml] [--set KEY=VALUE ...]
                              [--name startup] [--out benchmarks/results]

Runs ``python -m solver run SCENE --set ... --no-progress`` (default: Example 1, ``--set mesh.nx=128 --set
mesh.ny=128 --set time.k=0.005``, the run of issue 30; one rank, a fresh output directory) from ``--before``
(a ``git archive`` of that commit; default HEAD~1) and from this checkout, alternately (before, after, before,
after, ...), each in a new process.
Per run: the whole process's wall time; from its timeseries.csv the wall time of level 0 (its factorizations)
and of the steps 1..N. "Start-up and end" is the whole time less the steps: the interpreter, MPI, the imports,
the model's set-up, level 0, the last writes and the exit. Also timed alternately: a process that only imports
what a run imports (``import solver.cli, solver.io.results, solver.run.model``: MPI's start and end included).
Reported: medians over the repeats, the after/before ratios of the medians and the median of the ratios of the
adjacent pairs; and whether the two trees wrote the same results (every timeseries.csv column but the times,
every dataset of checkpoint.h5, bit for bit; else the max relative difference). Writes ``NAME.json`` and
``NAME.md`` under ``--out``.
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

import h5py
import numpy as np

ROOT = Path(__file__).resolve().parents[1]
IMPORTS = "import solver.cli, solver.io.results, solver.run.model"


def _export(rev: str, into: Path) -> Path:
    """The tree of commit ``rev`` under ``into`` (git archive)."""
    archive = subprocess.run(["git", "archive", rev], cwd=ROOT, check=True, capture_output=True).stdout
    subprocess.run(["tar", "-x", "-C", str(into)], input=archive, check=True)
    return into


ENV = dict(os.environ)  # the children's environment (--bytecode: with Python's bytecode cache, as a user has it)


def _cpu() -> float:
    """User + system seconds of the finished child processes so far."""
    r = resource.getrusage(resource.RUSAGE_CHILDREN)
    return r.ru_utime + r.ru_stime


def _run(tree: Path, out: Path, scene: str, overrides: list[str]) -> dict[str, float]:
    """One CLI run from ``tree``; its wall time and CPU time (user + system), level 0's and the steps' wall time
    (from the CSV)."""
    cmd = [sys.executable, "-m", "solver", "run", scene, *(a for o in overrides for a in ("--set", o)),
           "--no-progress", "--output", str(out)]
    t0, c0 = time.perf_counter(), _cpu()
    subprocess.run(cmd, cwd=tree, check=True, capture_output=True, env=ENV)
    total, cpu = time.perf_counter() - t0, _cpu() - c0
    rows = list(csv.DictReader(open(out / "timeseries.csv")))
    steps = sum(float(r["wall_time"]) for r in rows[1:])
    return {"total": total, "cpu": cpu, "level0": float(rows[0]["wall_time"]), "steps": steps,
            "startup_end": total - steps}


def _imports(tree: Path) -> float:
    t0 = time.perf_counter()
    subprocess.run([sys.executable, "-c", IMPORTS], cwd=tree, check=True, capture_output=True, env=ENV)
    return time.perf_counter() - t0


def _rel(a: np.ndarray, b: np.ndarray) -> float:
    """max |a - b| / max |a| (0 if equal; inf if the shapes differ)."""
    if a.shape != b.shape:
        return float("inf")
    scale = float(np.max(np.abs(a))) if a.size else 0.0
    return float(np.max(np.abs(a - b))) / (scale or 1.0) if a.size else 0.0


BUILD = ("import json, resource, sys, time; from mpi4py import MPI; from solver.config import load; "
         "from solver.run.model import build_model; t = time.perf_counter(); "
         "build_model(load(sys.argv[1], sys.argv[2:]), MPI.COMM_WORLD); "
         "print(json.dumps({'build': time.perf_counter() - t, "
         "'peak_mib': resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024}))")


def _build(tree: Path, scene: str, overrides: list[str]) -> dict[str, float]:
    """build_model alone in a new process from ``tree``: its time and the process's peak resident memory."""
    res = subprocess.run([sys.executable, "-c", BUILD, scene, *overrides], cwd=tree, check=True, capture_output=True,
                         text=True)
    return json.loads(res.stdout.strip().splitlines()[-1])


def build_only(args: argparse.Namespace, before_rev: str, after_rev: str) -> int:
    """``--build-only``: the model's set-up (build_model) before/after, alternated; NAME.json and NAME.md."""
    with tempfile.TemporaryDirectory() as tmp:
        trees = {"before": _export(args.before, Path(tmp)), "after": ROOT}
        runs: dict[str, list[dict]] = {"before": [], "after": []}
        for _ in range(args.repeats):
            for name, tree in trees.items():
                runs[name].append(_build(tree, args.scene, args.overrides))
                print(name, runs[name][-1], flush=True)
    med = {name: {key: statistics.median(r[key] for r in rs) for key in rs[0]} for name, rs in runs.items()}
    sets = " ".join(f"--set {o}" for o in args.overrides)
    text = "\n".join([
        f"# The model's set-up (build_model) of {args.scene} {sets} (one rank)", "",
        f"`python scripts/startup.py --build-only --before {before_rev} --scene {args.scene} {sets} --name {args.name}`:"
        f" before = {before_rev}, after = {after_rev}; {args.repeats} of each, alternated, each a new process; medians.",
        "", "| | before | after | after / before |", "|---|---|---|---|",
        f"| build_model (s) | {med['before']['build']:.2f} | {med['after']['build']:.2f} | "
        f"{med['after']['build'] / med['before']['build']:.3f} |",
        f"| peak resident memory of the process (MiB) | {med['before']['peak_mib']:.0f} | {med['after']['peak_mib']:.0f} | "
        f"{med['after']['peak_mib'] / med['before']['peak_mib']:.3f} |", ""])
    args.out.mkdir(parents=True, exist_ok=True)
    (args.out / f"{args.name}.json").write_text(json.dumps({"before": before_rev, "after": after_rev, "runs": runs,
                                                            "median": med}, indent=1) + "\n")
    (args.out / f"{args.name}.md").write_text(text)
    print(text)
    return 0


def _same_results(a: Path, b: Path) -> dict[str, float]:
    """What differs between two result directories, with its max relative difference: CSV columns (times excepted)
    and checkpoint datasets."""
    diff = {}
    ra, rb = list(csv.DictReader(open(a / "timeseries.csv"))), list(csv.DictReader(open(b / "timeseries.csv")))
    for col in ra[0]:
        if not (col.startswith("time_") or col == "wall_time") and [r[col] for r in ra] != [r.get(col) for r in rb]:
            diff[f"timeseries.csv:{col}"] = _rel(np.array([float(r[col]) for r in ra]),
                                                 np.array([float(r[col]) for r in rb]))
    with h5py.File(a / "checkpoint.h5") as ha, h5py.File(b / "checkpoint.h5") as hb:
        names: list[str] = []
        ha.visit(lambda name: names.append(name) if isinstance(ha[name], h5py.Dataset) else None)
        for name in names:
            if name not in hb:
                diff[f"checkpoint.h5:{name}"] = float("inf")
            elif not np.array_equal(ha[name][...], hb[name][...]):
                diff[f"checkpoint.h5:{name}"] = _rel(ha[name][...], hb[name][...])
    return diff


def pieces(scene: str, overrides: list[str], repeats: int) -> dict[str, list[float]]:
    """In this process, alternated: the FFCx cache lookups of a model's modules by FFCx's finder and by file name
    (formcache._direct), and the order of a checkpoint's points by the structured argsort and by lexsort."""
    sys.path.insert(0, str(ROOT))  # this checkout's solver
    from mpi4py import MPI

    from solver.config import load
    from solver.io import checkpoint
    from solver.run import formcache
    from solver.run.model import build_model

    formcache.install()
    model = build_model(load(scene, overrides), MPI.COMM_WORLD)
    modules = list(formcache._found)
    points = [f.coords[: f.owned] for f in checkpoint._fields(model).values()]
    out: dict[str, list[float]] = {"lookups_ffcx": [], "lookups_by_name": [], "order_argsort": [], "order_lexsort": []}
    for _ in range(repeats):
        t0 = time.perf_counter()
        for name, objects, cache in modules:
            formcache._disk_lookup(name, list(objects), cache, 10)
        t1 = time.perf_counter()
        for name, objects, cache in modules:
            formcache._direct(name, list(objects), cache)
        t2 = time.perf_counter()
        for c in points:
            np.argsort(checkpoint._keys(c))
        t3 = time.perf_counter()
        for c in points:
            checkpoint._order(c)
        t4 = time.perf_counter()
        for key, value in zip(out, (t1 - t0, t2 - t1, t3 - t2, t4 - t3)):
            out[key].append(value)
    out["modules"] = [len(modules)]
    out["points"] = [sum(len(c) for c in points)]
    return out


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--before", default="HEAD~1", help="the commit to compare with (default HEAD~1)")
    p.add_argument("--repeats", type=int, default=5)
    p.add_argument("--scene", default="configs/example1.toml")
    p.add_argument("--set", dest="overrides", action="append", metavar="SECTION.KEY=VALUE",
                   help="scene overrides (default: mesh.nx=128, mesh.ny=128, time.k=0.005)")
    p.add_argument("--name", default="startup", help="result files NAME.json and NAME.md")
    p.add_argument("--pieces", action="store_true", help=argparse.SUPPRESS)  # the child process of pieces()
    p.add_argument("--build-only", action="store_true", help="time only build_model (and its peak memory)")
    p.add_argument("--bytecode", action="store_true",
                   help="let the children use and write Python's bytecode cache (__pycache__) even where "
                        "PYTHONDONTWRITEBYTECODE is set (each tree is then run once before the timed runs)")
    p.add_argument("--out", type=Path, default=ROOT / "benchmarks" / "results")
    args = p.parse_args(argv)
    if args.bytecode:
        ENV.pop("PYTHONDONTWRITEBYTECODE", None)
    args.overrides = args.overrides or ["mesh.nx=128", "mesh.ny=128", "time.k=0.005"]
    if args.pieces:
        print(json.dumps(pieces(args.scene, args.overrides, args.repeats)))
        return 0
    before_rev = subprocess.run(["git", "rev-parse", "--short", args.before], cwd=ROOT, check=True,
                                capture_output=True, text=True).stdout.strip()
    after_rev = subprocess.run(["git", "describe", "--always", "--dirty"], cwd=ROOT, check=True,
                               capture_output=True, text=True).stdout.strip()
    if args.build_only:
        return build_only(args, before_rev, after_rev)
    with tempfile.TemporaryDirectory() as tmp:
        tmp = Path(tmp)
        trees = {"before": _export(args.before, Path(tempfile.mkdtemp(dir=tmp))), "after": ROOT}
        runs: dict[str, list[dict]] = {"before": [], "after": []}
        imports: dict[str, list[float]] = {"before": [], "after": []}
        if args.bytecode:  # the caches written before the timed runs
            for name, tree in trees.items():
                _run(tree, tmp / f"{name}-warm", args.scene, args.overrides)
        for i in range(args.repeats):
            for name, tree in trees.items():
                runs[name].append(_run(tree, tmp / f"{name}{i}", args.scene, args.overrides))
                imports[name].append(_imports(tree))
                print(name, i, {k: round(v, 3) for k, v in runs[name][-1].items()}, flush=True)
        differ = _same_results(tmp / "before0", tmp / "after0")
    child = [sys.executable, str(Path(__file__).resolve()), "--pieces", "--repeats", str(3 * args.repeats),
             "--scene", args.scene, *(a for o in args.overrides for a in ("--set", o))]
    parts = json.loads(subprocess.run(child, cwd=ROOT, check=True, capture_output=True, text=True).stdout)
    med = {name: {key: statistics.median(r[key] for r in rs) for key in rs[0]} for name, rs in runs.items()}
    for name in med:
        med[name]["imports"] = statistics.median(imports[name])
    result = {"before": before_rev, "after": after_rev, "scene": args.scene, "overrides": args.overrides,
              "repeats": args.repeats, "bytecode": args.bytecode, "dontwrite": ENV.get("PYTHONDONTWRITEBYTECODE"),
              "load": " ".join(f"{x:.1f}" for x in os.getloadavg()), "name": args.name,
              "median": med, "runs": runs, "imports": imports, "differ": differ, "pieces": parts,
              "ratio": {key: med["after"][key] / med["before"][key] for key in med["after"]},
              "pair_ratio": {key: statistics.median(a[key] / b[key] for a, b in zip(runs["after"], runs["before"]))
                             for key in runs["after"][0]}}
    result["pair_ratio"]["imports"] = statistics.median(a / b for a, b in zip(imports["after"], imports["before"]))
    args.out.mkdir(parents=True, exist_ok=True)
    (args.out / f"{args.name}.json").write_text(json.dumps(result, indent=1) + "\n")
    (args.out / f"{args.name}.md").write_text(_table(result))
    print(_table(result))
    return 0


def _table(r: dict) -> str:
    b, a = r["median"]["before"], r["median"]["after"]
    rows = [("whole run", "total"), ("whole run, CPU time (user + system)", "cpu"),
            ("start-up and end (whole less the steps)", "startup_end"),
            ("  of which level 0 (its factorizations)", "level0"), ("steps 1..N", "steps"),
            ("imports only (`python -c '" + IMPORTS + "'`)", "imports")]
    sets = " ".join(f"--set {o}" for o in r["overrides"])
    cache = ("used and written (--bytecode: as a user has it)" if r.get("bytecode") else
             f"as the environment says (PYTHONDONTWRITEBYTECODE={r.get('dontwrite')})")
    lines = [f"# Start-up of the CLI run of {r['scene']} {sets} (one rank)", "",
             f"`python scripts/startup.py --before {r['before']} --scene {r['scene']} {sets}"
             f"{' --bytecode' if r.get('bytecode') else ''} --name {r.get('name', 'startup')}`: "
             f"before = {r['before']}, after = {r['after']}; "
             f"{r['repeats']} runs of each, alternated, each a new process; medians in seconds. Python's bytecode "
             f"cache: {cache}; load average at the end {r.get('load', '?')} (2 cores).", "",
             "| | before | after | after / before (medians) | median of the pairs' ratios |", "|---|---|---|---|---|"]
    lines += [f"| {label} | {b[key]:.3f} | {a[key]:.3f} | {a[key] / b[key]:.3f} | {r['pair_ratio'][key]:.3f} |"
              for label, key in rows]
    lines += ["", f"Share of start-up and end in the whole run: before {b['startup_end'] / b['total']:.1%}, "
              f"after {a['startup_end'] / a['total']:.1%}.", "",
              _pieces_line(r["pieces"]), "",
              "Same results (every timeseries.csv column but the times; every dataset of checkpoint.h5, bit for bit): "
              + ("yes" if not r["differ"] else "bit for bit except (max relative difference): "
                 + ", ".join(f"{k} {v:.1e}" for k, v in r["differ"].items())), ""]
    return "\n".join(lines)


def _pieces_line(parts: dict) -> str:
    m = {key: statistics.median(v) for key, v in parts.items()}
    return (f"In one process, alternated ({len(parts['lookups_ffcx'])} times, medians): the {m['modules']:.0f} FFCx "
            f"modules of the model looked up by FFCx's finder {1e3 * m['lookups_ffcx']:.1f} ms, by file name "
            f"{1e3 * m['lookups_by_name']:.1f} ms; a checkpoint's {m['points']:,.0f} points ordered by the structured "
            f"argsort {1e3 * m['order_argsort']:.1f} ms, by lexsort {1e3 * m['order_lexsort']:.1f} ms (per write).")


if __name__ == "__main__":
    sys.exit(main())
