"""The plan a tolerance gives a scene (no run), as one JSON line: to compare the plan on 2 ranks with the serial one.

    .venv/bin/python scripts/plan_3d.py configs/column3d.toml 1e-2
    mpirun -n 2 .venv/bin/python scripts/plan_3d.py configs/column3d.toml 1e-2
"""

from __future__ import annotations

import json
import sys
from pathlib import Path

from mpi4py import MPI

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from solver.config import load  # noqa: E402
from solver.run.accuracy.planner import plan  # noqa: E402


def main() -> int:
    scene, tol = sys.argv[1], float(sys.argv[2])
    comm = MPI.COMM_WORLD
    log = print if comm.rank == 0 else (lambda *a: None)
    p = plan(load(scene, ["output.xdmf=false", f"accuracy.tolerance={tol}"]), comm, log=log)
    out = {"scene": scene, "tol": tol, "ranks": comm.size, "degree": p.degree, "order": p.order, "k": p.k,
           "cells": p.geo.num_cells(), "estimate": p.estimate.as_dict(), "sequence": [r.cells for r in p.adaptation],
           "planning_seconds": p.seconds}
    if comm.rank == 0:
        print(json.dumps(out))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
