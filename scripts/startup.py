"""Start-up of the whole CLI run of Example 1 (issue 30): this checkout against an earlier commit, alternated.

    python scripts/startup.py [--before REV] [--repeats 5] [--n 128] [--k 0.005] [--out benchmarks/results]

Runs ``python -m solver run configs/example1.toml --set mesh.nx=N --set mesh.ny=N --set time.k=K --no-progress``
(one rank, a fresh output directory) from ``--before`` (a ``git archive`` of that commit; default HEAD~1) and
from this checkout, alternately (before, after, before, after, ...), each in a new process.
Per run: the whole process's wall time; from its timeseries.csv the wall time of level 0 (its factorizations)
and of the steps 1..N. "Start-up and end" is the whole time less the steps: the interpreter, MPI, the imports,
the model's set-up, level 0, the last writes and the exit. Also timed alternately: a process that only imports
what a run imports (``import solver.cli, solver.io.results, solver.run.model``: MPI's start and end included).
Reported: medians over the repeats and the after/before ratios of the medians; and whether the two trees wrote
the same results (every timeseries.csv column but the times, every dataset of checkpoint.h5, bit for bit).
Writes ``startup.json`` and ``startup.md`` under ``--out``.
"""

from __future__ import annotations

import argparse
import csv
import json
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


def _run(tree: Path, out: Path, n: int, k: float) -> dict[str, float]:
    """One CLI run from ``tree``; its wall time, level 0's and the steps' (from the CSV)."""
    cmd = [sys.executable, "-m", "solver", "run", "configs/example1.toml", "--set", f"mesh.nx={n}",
           "--set", f"mesh.ny={n}", "--set", f"time.k={k}", "--no-progress", "--output", str(out)]
    t0 = time.perf_counter()
    subprocess.run(cmd, cwd=tree, check=True, capture_output=True)
    total = time.perf_counter() - t0
    rows = list(csv.DictReader(open(out / "timeseries.csv")))
    steps = sum(float(r["wall_time"]) for r in rows[1:])
    return {"total": total, "level0": float(rows[0]["wall_time"]), "steps": steps, "startup_end": total - steps}


def _imports(tree: Path) -> float:
    t0 = time.perf_counter()
    subprocess.run([sys.executable, "-c", IMPORTS], cwd=tree, check=True, capture_output=True)
    return time.perf_counter() - t0


def _same_results(a: Path, b: Path) -> list[str]:
    """What differs between two result directories: CSV columns (times excepted) and checkpoint datasets."""
    diff = []
    ra, rb = list(csv.DictReader(open(a / "timeseries.csv"))), list(csv.DictReader(open(b / "timeseries.csv")))
    for col in ra[0]:
        if not (col.startswith("time_") or col == "wall_time") and [r[col] for r in ra] != [r.get(col) for r in rb]:
            diff.append(f"timeseries.csv:{col}")
    with h5py.File(a / "checkpoint.h5") as ha, h5py.File(b / "checkpoint.h5") as hb:
        names: list[str] = []
        ha.visit(lambda name: names.append(name) if isinstance(ha[name], h5py.Dataset) else None)
        diff += [f"checkpoint.h5:{name}" for name in names if name not in hb
                 or not np.array_equal(ha[name][...], hb[name][...])]
    return diff


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--before", default="HEAD~1", help="the commit to compare with (default HEAD~1)")
    p.add_argument("--repeats", type=int, default=5)
    p.add_argument("--n", type=int, default=128)
    p.add_argument("--k", type=float, default=0.005)
    p.add_argument("--out", type=Path, default=ROOT / "benchmarks" / "results")
    args = p.parse_args(argv)
    before_rev = subprocess.run(["git", "rev-parse", "--short", args.before], cwd=ROOT, check=True,
                                capture_output=True, text=True).stdout.strip()
    after_rev = subprocess.run(["git", "describe", "--always", "--dirty"], cwd=ROOT, check=True,
                               capture_output=True, text=True).stdout.strip()
    with tempfile.TemporaryDirectory() as tmp:
        tmp = Path(tmp)
        trees = {"before": _export(args.before, Path(tempfile.mkdtemp(dir=tmp))), "after": ROOT}
        runs: dict[str, list[dict]] = {"before": [], "after": []}
        imports: dict[str, list[float]] = {"before": [], "after": []}
        for i in range(args.repeats):
            for name, tree in trees.items():
                runs[name].append(_run(tree, tmp / f"{name}{i}", args.n, args.k))
                imports[name].append(_imports(tree))
                print(name, i, {k: round(v, 3) for k, v in runs[name][-1].items()}, flush=True)
        differ = _same_results(tmp / "before0", tmp / "after0")
    med = {name: {key: statistics.median(r[key] for r in rs) for key in rs[0]} for name, rs in runs.items()}
    for name in med:
        med[name]["imports"] = statistics.median(imports[name])
    result = {"before": before_rev, "after": after_rev, "n": args.n, "k": args.k, "repeats": args.repeats,
              "median": med, "runs": runs, "imports": imports, "differ": differ,
              "ratio": {key: med["after"][key] / med["before"][key] for key in med["after"]}}
    args.out.mkdir(parents=True, exist_ok=True)
    (args.out / "startup.json").write_text(json.dumps(result, indent=1) + "\n")
    (args.out / "startup.md").write_text(_table(result))
    print(_table(result))
    return 0


def _table(r: dict) -> str:
    b, a = r["median"]["before"], r["median"]["after"]
    rows = [("whole run", "total"), ("start-up and end (whole less the steps)", "startup_end"),
            ("  of which level 0 (its factorizations)", "level0"), ("steps 1..N", "steps"),
            ("imports only (`python -c '" + IMPORTS + "'`)", "imports")]
    lines = [f"# Start-up of the CLI run of Example 1 (n = {r['n']}, k = {r['k']}, one rank)", "",
             f"`python scripts/startup.py --before {r['before']}`: before = {r['before']}, after = {r['after']}; "
             f"{r['repeats']} runs of each, alternated, each a new process; medians in seconds.", "",
             "| | before | after | after / before |", "|---|---|---|---|"]
    lines += [f"| {label} | {b[key]:.3f} | {a[key]:.3f} | {a[key] / b[key]:.3f} |" for label, key in rows]
    lines += ["", f"Share of start-up and end in the whole run: before {b['startup_end'] / b['total']:.1%}, "
              f"after {a['startup_end'] / a['total']:.1%}.", "",
              "Same results (every timeseries.csv column but the times; every dataset of checkpoint.h5, bit for bit): "
              + ("yes" if not r["differ"] else "NO: " + ", ".join(r["differ"])), ""]
    return "\n".join(lines)


if __name__ == "__main__":
    sys.exit(main())
