"""After a failed Krylov solve: the direct solver for the rest of the run, or the iterative one again after the
level that needed it (``solver.solvers.newton.DIRECT_LEVELS``), side by side, alternated.

    python benchmarks/direct_retry.py [--rounds 2] [--levels 3] [--out benchmarks/results/direct_retry]

The scene: first_contact.py's 3-D sphere (radius 2 into the quarter block, gmsh mesh graded to 0.015 by
meshes/hertz3d.py, P1, mu = 1e-8) under the default settings (auto; the linear solver auto picks, iterative for
this short run) but ``solver.max_it = --max-it`` (default 100, as first measured; the default setting 25 gives the
same levels since auto gives every level after its hand-over the fallback's budget),
its top pushed from 0.015 at t = 0 to ``--depth`` (0.018) at t = 1 in ``--levels`` levels: level 0's first
contact fails CG + GAMG and is solved by MUMPS (auto.py), the later levels press the contact zone wider. Each
variant runs in its own process, variant after variant, ``--rounds`` times. Writes OUT.csv (one row a run: the
variant, its seconds for the levels, iterations, factorizations and contact force per level, the switches to the
direct solver) and prints the median and range of the time ratio and the largest relative difference of the
levels' contact forces between the variants.
"""

from __future__ import annotations

import argparse
import csv
import json
import os
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "benchmarks"))

VARIANTS = {"stay_direct": None, "back_after_1": 1}


def one(scene: dict, levels: int, direct_levels: int | None) -> dict:
    """The scene's first ``levels`` levels with DIRECT_LEVELS = ``direct_levels``."""
    from mpi4py import MPI

    import solver.solvers.newton as newton
    assert Path(newton.__file__).is_relative_to(ROOT), newton.__file__
    from solver.config import from_dict
    from solver.run.model import build_model
    from solver.run.stepper import Stepper

    newton.DIRECT_LEVELS = direct_levels
    model = build_model(from_dict(scene), MPI.COMM_WORLD)
    stepper = Stepper(model)
    t = time.perf_counter()
    rows = [stepper.step(n) for n in range(levels)]
    seconds = time.perf_counter() - t
    core = model.mech.solver.core
    return {"seconds": seconds, "iterations": [r["newton_iterations"] for r in rows],
            "factorizations": [r["factorizations"] for r in rows],
            "contact_force": [r["contact_force"] for r in rows], "direct_switches": core.direct_switches}


def main() -> int:
    from first_contact import sphere

    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--rounds", type=int, default=2)
    parser.add_argument("--levels", type=int, default=3)
    parser.add_argument("--h", type=float, default=0.015)
    parser.add_argument("--max-it", type=int, default=100, help="solver.max_it (the scene default is 25, "
                        "which gives the same levels: auto's take-over has 8 x max_it on every level)")
    parser.add_argument("--depth", type=float, default=0.018, help="the push at t = 1 (0.015 at t = 0)")
    parser.add_argument("--one", nargs=2, help=argparse.SUPPRESS)
    parser.add_argument("--out", default=str(ROOT / "benchmarks" / "results" / "direct_retry"))
    args = parser.parse_args()
    if args.one:
        scene = json.loads(Path(args.one[0]).read_text())
        levels = scene.pop("levels")
        print(json.dumps(one(scene, levels, None if args.one[1] == "None" else int(args.one[1]))))
        return 0
    work = Path(tempfile.mkdtemp(prefix="direct_retry_"))
    msh = work / "hertz3d.msh"
    subprocess.run([sys.executable, str(ROOT / "meshes" / "hertz3d.py"), "--h", str(args.h), "--output", str(msh)],
                   check=True)
    scene = sphere(str(msh))
    scene["time"] = {"T": 1.0, "k": 1.0 / (args.levels - 1)}
    scene["boundary"]["top"]["displacement"] = ["free", "free", [[0.0, -0.015], [1.0, -args.depth]]]
    scene["solver"] = {"max_it": args.max_it}
    path = work / "scene.json"
    path.write_text(json.dumps({**scene, "levels": args.levels}))
    rows = []
    for r in range(args.rounds):
        for name, value in VARIANTS.items():
            done = subprocess.run([sys.executable, str(Path(__file__).resolve()), "--one", str(path), str(value)],
                                  cwd=ROOT, capture_output=True, text=True, env={**os.environ, "PYTHONPATH": str(ROOT)})
            if done.returncode != 0:
                print(done.stderr[-2000:], file=sys.stderr)
                rows.append({"round": r, "variant": name, "failure": done.stderr.strip().splitlines()[-1][:200]})
                continue
            rows.append({"round": r, "variant": name, **json.loads(done.stdout.strip().splitlines()[-1])})
            print(rows[-1], flush=True)
    with open(f"{args.out}.csv", "w", newline="") as f:
        w = csv.DictWriter(f, ["round", "variant", "seconds", "iterations", "factorizations", "contact_force",
                               "direct_switches", "failure"])
        w.writeheader()
        w.writerows(rows)
    a, b = list(VARIANTS)
    if any("failure" in r for r in rows):
        return 1
    ratios = sorted(y["seconds"] / x["seconds"] for x, y in zip(rows[0::2], rows[1::2]))
    diff = max(abs(p - q) / abs(p) for x, y in zip(rows[0::2], rows[1::2])
               for p, q in zip(x["contact_force"], y["contact_force"]))
    print(f"{b} / {a} time: median {statistics.median(ratios):.3f}, range {ratios[0]:.3f}-{ratios[-1]:.3f}; "
          f"contact forces differ by at most {diff:.2e} relative")
    return 0


if __name__ == "__main__":
    sys.exit(main())
