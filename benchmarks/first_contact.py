"""First contact's Newton iterations, two trees side by side: the Hertz scenes of docs/model.md §4.

    python benchmarks/first_contact.py --base CHECKOUT_OF_THE_BASE [--only 2d] [--rounds N] [--out benchmarks/results/first_contact]
    python benchmarks/first_contact.py --points gauss nodes [--only sphere] [--h 0.03] [--out ...]

Each case's first level (t = 0, the elastic contact problem) is solved under the default settings (``auto``) by
each tree in its own process (``one`` below, run with that tree on PYTHONPATH), base then this tree, case after
case, on the same machine in the same run; with ``--rounds N`` N times, the trees' order swapped every round, and
the ratio this / base of each round's seconds printed (median and range). Cases: Hertz line contact (a half block
(0, 1)² pushed 0.005 onto g = x²/2, mu = 1e-8) at P1 n = 200 and P2 n = 100; the 3-D sphere (radius 2 pressed
0.015 into the quarter block (0, 2)³ with symmetry planes, gmsh mesh graded to 0.015 at the contact by
meshes/hertz3d.py, P1, mu = 1e-8; ``--h`` another size at the contact).
With ``--points A B ...`` this tree runs each case once per value of ``solver.contact_points`` (the contact law at the
Gauss points or at the nodes), alternated as the trees are (the ratios are then of the second value over the first).
Writes OUT.csv (case, round, tree, points, iterations, factorizations, contact force, contact length (area in 3-D),
peak pressure, the level's solve time (level_seconds: the row's time_displacement), the process's seconds or the
failure) and prints it.
"""

from __future__ import annotations

import argparse
import csv
import json
import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]


def line_contact(n: int, degree: int) -> dict:
    s = np.linspace(0.0, 1.0, 5)
    return {"memory": {"kernel": "none"}, "damage": {"enabled": False}, "time": {"T": 1.0, "k": 1.0},
            "mesh": {"nx": n, "ny": n}, "material": {"E": 1.0, "nu": 0.3}, "discretization": {"u_degree": degree},
            "boundary": {"left": {"role": "displacement", "displacement": [0.0, "free"]},
                         "top": {"role": "displacement", "displacement": ["free", -0.005]},
                         "bottom": {"role": "contact", "mu": 1e-8, "gap": [[v, v * v / 2] for v in s.tolist()],
                                    "gap_coordinate": "x", "gap_interpolation": "cubic"}}}


def sphere(msh: str) -> dict:
    return {"memory": {"kernel": "none"}, "damage": {"enabled": False}, "time": {"T": 1.0, "k": 1.0},
            "mesh": {"kind": "gmsh", "file": msh}, "material": {"E": 1.0, "nu": 0.3, "model": "3d"},
            "boundary": {"sym_x": {"role": "displacement", "displacement": [0.0, "free", "free"]},
                         "sym_y": {"role": "displacement", "displacement": ["free", 0.0, "free"]},
                         "top": {"role": "displacement", "displacement": ["free", "free", -0.015]},
                         "bottom": {"role": "contact", "mu": 1e-8,
                                    "obstacle": {"shape": "sphere", "centre": [0.0, 0.0, -2.0], "radius": 2.0}}}}


def one(scene: dict) -> dict:
    """The first level of ``scene`` by the solver on sys.path (the tree under test)."""
    from mpi4py import MPI

    from solver.config import from_dict
    from solver.run.model import build_model
    from solver.run.stepper import Stepper

    t = time.perf_counter()
    model = build_model(from_dict(scene), MPI.COMM_WORLD)
    try:
        row = Stepper(model).step(0)
    except Exception as exc:  # a failed level is a result here
        return {"failure": str(exc).splitlines()[0][:160], "seconds": time.perf_counter() - t}
    return {"iterations": row["newton_iterations"], "factorizations": row["factorizations"],
            "contact_force": row["contact_force"], "contact_length": row["contact_length"],
            "peak_pressure": row.get("peak_pressure", ""), "level_seconds": row["time_displacement"],
            "seconds": time.perf_counter() - t}


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    sub = parser.add_subparsers(dest="cmd")
    o = sub.add_parser("one")
    o.add_argument("scene")
    parser.add_argument("--base", help="a checkout of the base tree")
    parser.add_argument("--only", nargs="*", default=[], help="cases whose name contains one of these")
    parser.add_argument("--out", default=str(ROOT / "benchmarks" / "results" / "first_contact"))
    parser.add_argument("--rounds", type=int, default=1, help="rounds, the trees' order swapped every round")
    parser.add_argument("--points", nargs="*", default=[], help="values of solver.contact_points this tree runs")
    parser.add_argument("--h", type=float, default=0.015, help="the sphere mesh's size at the contact")
    args = parser.parse_args()
    if args.cmd == "one":
        print(json.dumps(one(json.loads(Path(args.scene).read_text()))))
        return 0
    work = Path(tempfile.mkdtemp(prefix="first_contact_"))
    msh = work / "hertz3d.msh"
    cases = {"line_P1_n200": line_contact(200, 1), "line_P2_n100": line_contact(100, 2), f"sphere3d_h{args.h:g}": None}
    if not args.only or any(o in "sphere3d" for o in args.only):
        subprocess.run([sys.executable, str(ROOT / "meshes" / "hertz3d.py"), "--h", str(args.h), "--output", str(msh)],
                       check=True)
        cases[f"sphere3d_h{args.h:g}"] = sphere(str(msh))
    # (label, tree, solver.contact_points or None: the tree's default)
    trees = ([("base", Path(args.base).resolve(), None)] if args.base else []) + [
        ("this" if len(args.points) < 2 else p, ROOT, p) for p in (args.points or [None])]
    first, second = trees[0][0], trees[-1][0]
    rows = []
    for name, scene in cases.items():
        if args.only and not any(o in name for o in args.only):
            continue
        for k in range(args.rounds):
            for tree, src, points in (trees if k % 2 == 0 else trees[::-1]):
                path = work / f"{name}_{points}.json"
                solver = {} if points is None else {"solver": {"contact_points": points}}
                path.write_text(json.dumps({**scene, **solver}))
                env = {**os.environ, "PYTHONPATH": str(src)}
                done = subprocess.run([sys.executable, str(Path(__file__).resolve()), "one", str(path)], env=env,
                                      cwd=src, capture_output=True, text=True)
                out = json.loads(done.stdout.strip().splitlines()[-1]) if done.returncode == 0 else {
                    "failure": done.stderr.strip().splitlines()[-1:]}
                rows.append({"case": name, "round": k, "tree": tree, "points": points or "", **out})
                print(rows[-1], flush=True)
        for column in ("seconds", "level_seconds"):
            seconds = {(r["round"], r["tree"]): r.get(column) for r in rows if r["case"] == name}
            ratios = [seconds[k, second] / seconds[k, first] for k in range(args.rounds)
                      if seconds.get((k, first)) and seconds.get((k, second))]
            if ratios and first != second:
                print(f"{name}: {column} {second} / {first} median {np.median(ratios):.2f} (range {min(ratios):.2f}-"
                      f"{max(ratios):.2f}, {len(ratios)} rounds)", flush=True)
    keys = ["case", "round", "tree", "points", "iterations", "factorizations", "contact_force", "contact_length", "peak_pressure",
            "level_seconds", "seconds", "failure"]
    with open(f"{args.out}.csv", "w", newline="") as f:
        w = csv.DictWriter(f, keys)
        w.writeheader()
        for r in rows:
            w.writerow({k: r.get(k, "") for k in keys})
    return 0


if __name__ == "__main__":
    sys.exit(main())
