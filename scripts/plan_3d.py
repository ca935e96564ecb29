"""The plan a tolerance gives a scene (no run), as one JSON line: to compare the plan on 2 ranks with the serial one.

With ``--dorfler N``: instead of the plan, the planner's first N Dörfler steps for P1 on the scene's start mesh with
a fixed fraction (``--theta``, 0.5), each mesh solved as the planner's probe solves it (``--at largest``: coarse-step
runs at ``--k`` to the level of largest eta, as column3d's plans are; ``--at 0``: the t = 0 problem), printing per
mesh the cells, eta, the marked cells and a digest of the sorted cell midpoints (the same digest: the same cells);
``--plain-plaza`` refines without ``adapt.TIE_BREAK``.

    .venv/bin/python scripts/plan_3d.py configs/column3d.toml 1e-2
    mpirun -n 2 .venv/bin/python scripts/plan_3d.py configs/column3d.toml 1e-2
    mpirun -n 2 .venv/bin/python scripts/plan_3d.py configs/column3d.toml --dorfler 2 --k 0.1
"""

from __future__ import annotations

import argparse
import hashlib
import json
import sys
import time
from pathlib import Path

import numpy as np
from mpi4py import MPI

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from solver.config import load  # noqa: E402
from solver.run.accuracy.planner import plan  # noqa: E402


def digest(geo) -> str:
    """A digest of all ranks' cell midpoints (rounded, sorted): equal for the same cells on any partition."""
    from dolfinx import mesh as dmesh

    n = geo.mesh.topology.index_map(geo.dim).size_local
    mid = dmesh.compute_midpoints(geo.mesh, geo.dim, np.arange(n, dtype=np.int32))
    key = np.round(np.concatenate(geo.comm.allgather(mid)), 9)
    return hashlib.sha1(key[np.lexsort(key.T[::-1])].tobytes()).hexdigest()[:12]


def dorfler_steps(scene: str, steps: int, theta: float, k: float, at: str, comm: MPI.Comm) -> dict:
    """The Dörfler sequence (module docstring)."""
    from solver.mesh.adapt import refine
    from solver.mesh.geometry import build
    from solver.physics.estimator import dorfler
    from solver.run.accuracy.scene import degrees, start_mesh, step, with_changes
    from solver.run.accuracy.solves import solve_largest_level, solve_level0

    cfg = load(scene, ["output.xdmf=false"])
    cfg = with_changes(cfg, start_mesh(cfg, comm), degrees(1), step(k), {"time": {"order": 2}})
    geo = build(comm, cfg.mesh, cfg.boundaries, cfg.dim)
    rows, started = [], time.perf_counter()
    for i in range(steps + 1):
        lv = solve_largest_level(cfg, comm, geo) if at == "largest" else solve_level0(cfg, comm, geo)
        row = {"cells": geo.num_cells(), "eta": lv.indicator, "digest": digest(geo)}
        if i < steps:
            marked = np.flatnonzero(dorfler(lv.cell_indicators, theta, comm))
            row["marked"] = comm.allreduce(len(marked), op=MPI.SUM)
            geo = refine(lv.model.geo, marked)
        rows.append(row)
        if comm.rank == 0:
            print(row, flush=True)
    return {"scene": scene, "ranks": comm.size, "theta": theta, "k": k, "at": at, "steps": rows,
            "seconds": time.perf_counter() - started}


def main() -> int:
    ap = argparse.ArgumentParser()
    ap.add_argument("scene")
    ap.add_argument("tol", type=float, nargs="?")
    ap.add_argument("--dorfler", type=int, default=0)
    ap.add_argument("--theta", type=float, default=0.5)
    ap.add_argument("--k", type=float, default=0.1)
    ap.add_argument("--at", choices=("largest", "0"), default="largest")
    ap.add_argument("--plain-plaza", action="store_true",
                    help="refine without adapt.TIE_BREAK (dolfinx's own tie-break: to show the difference)")
    args = ap.parse_args()
    if args.plain_plaza:
        from dolfinx import mesh as dmesh

        import solver.mesh.adapt as adapt

        adapt._plaza = lambda mesh, edges: dmesh.refine(mesh, edges, redistribute=False)
    comm = MPI.COMM_WORLD
    if args.dorfler:
        out = dorfler_steps(args.scene, args.dorfler, args.theta, args.k, args.at, comm)
    else:
        log = print if comm.rank == 0 else (lambda *a: None)
        p = plan(load(args.scene, ["output.xdmf=false", f"accuracy.tolerance={args.tol}"]), comm, log=log)
        out = {"scene": args.scene, "tol": args.tol, "ranks": comm.size, "degree": p.degree, "order": p.order,
               "k": p.k, "cells": p.geo.num_cells(), "estimate": p.estimate.as_dict(),
               "sequence": [r.cells for r in p.adaptation], "digest": digest(p.geo), "planning_seconds": p.seconds}
    if comm.rank == 0:
        print(json.dumps(out))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
