"""Newton iterations per level on the moving-contact scenes, two trees one after the other (docs/model.md §4).

    python benchmarks/moving_contact_iterations.py [--base CHECKOUT_OF_THE_BASE] [--rounds N] [--out PATH_WITHOUT_SUFFIX]
    python benchmarks/moving_contact_iterations.py --points gauss nodes [--rounds N] [--out ...]

Each scene is run under the default settings (``auto``) at P2, order 2, with ``python -m solver run`` of the base
tree then of this one (each tree on PYTHONPATH, cwd its root), scene after scene, on the same machine in the same
run: configs/moving_contact.toml at n = 32 and configs/hard.toml at n = 48; without --base, this tree alone.
Writes OUT.csv (scene, tree, total Newton iterations, largest on a level, the levels above 10 as level:iterations,
and the displacement solves' time, the sum of timeseries.csv's time_displacement) from each run's timeseries.csv
and prints it. With --rounds N > 1 each scene is run N times, base and this tree alternated (base, this, base,
this ...), and the median and range of this tree's displacement time over the base's, round by round, are added
(the iteration counts are the same in every round: the switch and the iterations depend on the iterates only).
With ``--points A B`` this tree runs each scene with ``solver.contact_points`` = A and = B (the contact law at the
Gauss points or at the nodes), alternated as the trees are, and the ratio is B's time over A's; the rows then also
carry the contact force, peak pressure and contact length at the end and their largest difference over the levels
from A's (relative to A's largest). ``--set KEY=VALUE`` (repeatable) adds a scene override to this tree's runs
(e.g. ``--set solver.method=newton_condensed``).
"""

from __future__ import annotations

import argparse
import csv
import os
import statistics
import subprocess
import sys
import tempfile
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
P2 = ["discretization.u_degree=2", "discretization.zeta_degree=2", "time.order=2", "output.xdmf=false"]
SCENES = {"moving_contact_n32": ("configs/moving_contact.toml", 32), "hard_n48": ("configs/hard.toml", 48)}


def run(tree: Path, scene: str, n: int, out: Path, points: str | None = None,
        extra: tuple[str, ...] = ()) -> tuple[list[int], float, list[dict]]:
    """The Newton iterations of every level of ``scene`` at n by the solver of ``tree`` (``points``: its
    solver.contact_points; ``extra``: more overrides), the displacement solves' time (s) over the run, and the time
    series' rows."""
    sets = [*P2, f"mesh.nx={n}", f"mesh.ny={n}", f"output.directory='{out}'", *extra]
    if points is not None:
        sets.append(f"solver.contact_points='{points}'")
    cmd = [sys.executable, "-m", "solver", "run", str(tree / scene)]
    for s in sets:
        cmd += ["--set", s]
    subprocess.run(cmd, cwd=tree, env={**os.environ, "PYTHONPATH": str(tree)}, check=True, capture_output=True)
    with open(out / "timeseries.csv", newline="") as f:
        rows = list(csv.DictReader(f))
    return ([int(row["newton_iterations"]) for row in rows], sum(float(row["time_displacement"]) for row in rows),
            rows)


def largest_difference(rows: list[dict], ref: list[dict], column: str) -> float:
    """max over the levels of |a - b| / max |b| of a time series column (b: the reference run's)."""
    a = [float(r[column]) for r in rows]
    b = [float(r[column]) for r in ref]
    return max(abs(x - y) for x, y in zip(a, b, strict=True)) / max(abs(y) for y in b)


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--base", help="a checkout of the base tree (none: this tree alone)")
    parser.add_argument("--rounds", type=int, default=1, help="runs of each scene, base and this tree alternated")
    parser.add_argument("--out", default=str(ROOT / "benchmarks" / "results" / "moving_contact_iterations_runs"))
    parser.add_argument("--points", nargs="*", default=[], help="values of solver.contact_points this tree runs")
    parser.add_argument("--set", action="append", default=[], help="a scene override of this tree's runs, KEY=VALUE")
    args = parser.parse_args()
    work = Path(tempfile.mkdtemp(prefix="moving_contact_"))
    rows = []
    trees = ([("base", Path(args.base).resolve(), None)] if args.base else []) + [
        ("this" if len(args.points) < 2 else p, ROOT, p) for p in (args.points or [None])]
    first, second = trees[0][0], trees[-1][0]
    for name, (scene, n) in SCENES.items():
        times: dict[str, list[float]] = {tree: [] for tree, _, _ in trees}
        series: dict[str, list[dict]] = {}
        for k in range(args.rounds):
            for tree, src, points in (trees if k % 2 == 0 else trees[::-1]) if args.points else trees:
                extra = tuple(args.set) if src == ROOT else ()
                its, seconds, series_rows = run(src, scene, n, work / f"{name}_{tree}_{k}", points, extra)
                times[tree].append(seconds)
                if k == 0:
                    series[tree] = series_rows
                    above = " ".join(f"{i}:{j}" for i, j in enumerate(its) if j > 10)
                    rows.append({"scene": name, "tree": tree, "settings": " ".join(extra), "total": sum(its),
                                 "largest": max(its), "above_10": above,
                                 "factorizations": sum(int(r["factorizations"]) for r in series_rows)})
                print(name, tree, k, sum(its), f"{seconds:.3f} s", flush=True)
        for tree, _, _ in trees:
            row = next(r for r in rows if r["scene"] == name and r["tree"] == tree)
            row["time_displacement_median"] = f"{statistics.median(times[tree]):.3f}"
            if len(args.points) > 1:
                for column in ("contact_force", "peak_pressure", "contact_length"):  # where both runs write it
                    row[f"{column}_end"] = series[tree][-1].get(column, "")
                    if column in series[tree][-1] and column in series[first][-1]:
                        row[f"{column}_largest_difference"] = \
                            f"{largest_difference(series[tree], series[first], column):.3e}"
            if first != second:
                ratios = [a / b for a, b in zip(times[second], times[first], strict=True)]
                row[f"{second}_over_{first}_median"] = f"{statistics.median(ratios):.3f}"
                row[f"{second}_over_{first}_range"] = f"{min(ratios):.3f}-{max(ratios):.3f}"
            print(row, flush=True)
    with open(f"{args.out}.csv", "w", newline="") as f:
        w = csv.DictWriter(f, list(dict.fromkeys(k for r in rows for k in r)))
        w.writeheader()
        w.writerows(rows)
    return 0


if __name__ == "__main__":
    sys.exit(main())
