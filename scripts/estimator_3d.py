"""The residual estimator's constant C = error / eta on tetrahedra (the t = 0 problem of a 3-D scene).

The t = 0 (elastic contact) problem is solved with P1 and P2 on the planner's start mesh L0 and its uniform
refinement L1, on P2 meshes adapted from L0 by Dörfler marking (theta = 0.5), and (``--plan TOL ...``) on the
meshes the planner chooses for those tolerances; the reference is P2 on L0 refined uniformly twice (L2).
D = ||eps(u_ref - u_h)|| by ``studies.reference.PointwiseError`` (the judged run's cells, a degree-4 rule).
The reference's own error e_ref comes from the P2 differences of L0 and L1 to it, with errors e_l = A q^l and
Galerkin orthogonality (D_l^2 = e_l^2 - e_ref^2): q^2 = 1 / ((D_0 / D_1)^2 - 1), e_ref = D_1 q / sqrt(1 - q^2).
The error of a judged solution is then sqrt(D^2 + e_ref^2) (orthogonality) and at most D + e_ref (triangle
inequality); C = error / eta is given for both. Serial. Writes benchmarks/results/estimator_3d_<scene>.json and
prints a markdown table.

    .venv/bin/python scripts/estimator_3d.py configs/example1_3d.toml [--adapted 2] [--plan 1e-2 3e-3]
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path

import numpy as np
from mpi4py import MPI

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from solver.config import load  # noqa: E402
from solver.mesh.adapt import refine, refine_uniformly  # noqa: E402
from solver.mesh.geometry import build  # noqa: E402
from solver.physics.estimator import dorfler  # noqa: E402
from solver.run.accuracy.scene import degrees, start_mesh, with_changes  # noqa: E402
from solver.run.accuracy.solves import solve_level0  # noqa: E402
from studies.reference import PointwiseError  # noqa: E402


def main() -> int:
    ap = argparse.ArgumentParser()
    ap.add_argument("scene")
    ap.add_argument("--adapted", type=int, default=2, help="Dörfler steps of P2 from L0")
    ap.add_argument("--plan", type=float, nargs="*", default=[], help="tolerances whose planned mesh is judged")
    args = ap.parse_args()
    comm = MPI.COMM_SELF
    cfg = load(args.scene, ["output.xdmf=false"])
    cfg = with_changes(cfg, start_mesh(cfg, comm))
    two_mu = cfg.material.E / (1.0 + cfg.material.nu)
    t0 = time.perf_counter()
    L = [build(comm, cfg.mesh, cfg.boundaries, cfg.dim)]
    for _ in range(2):
        L.append(refine_uniformly(L[-1]))
    ref = solve_level0(with_changes(cfg, degrees(2)), comm, L[2])
    print(f"reference P2 on {L[2].num_cells()} cells, {ref.dofs} dofs: {time.perf_counter() - t0:.1f} s", flush=True)
    u_ref = ref.model.u.x.array
    V_ref = ref.model.u.function_space
    rows = []

    def judge(what, lv, **extra):
        err = PointwiseError(V_ref, None, lv.model)(u_ref, None)[0]
        rows.append({"what": what, "degree": lv.model.cfg.discretization.u_degree, "cells": lv.model.geo.num_cells(),
                     "dofs": lv.dofs, "eta": lv.indicator, "error": err, **extra})
        print(rows[-1], flush=True)

    for d in (1, 2):
        for i in (0, 1):
            judge(f"uniform L{i}", solve_level0(with_changes(cfg, degrees(d)), comm, L[i]))
    p2 = {r["what"]: r["error"] for r in rows if r["degree"] == 2}
    d02, d12 = p2["uniform L0"], p2["uniform L1"]
    q = (1.0 / ((d02 / d12) ** 2 - 1.0)) ** 0.5 if d02 > 1.5 * d12 else 0.75
    own = d12 * q / (1.0 - q * q) ** 0.5
    geo = L[0]
    lv = solve_level0(with_changes(cfg, degrees(2)), comm, geo)
    for j in range(args.adapted):
        geo = refine(lv.model.geo, np.flatnonzero(dorfler(lv.cell_indicators, 0.5, comm)))
        lv = solve_level0(with_changes(cfg, degrees(2)), comm, geo)
        judge(f"adapted {j + 1}", lv)
    for tol in args.plan:
        from solver.run.accuracy.planner import plan

        p = plan(cfg.replace({"accuracy": {"tolerance": tol}}), comm, log=lambda *a: None)
        judge(f"planned for TOL {tol:g}", solve_level0(with_changes(cfg, degrees(p.degree)), comm, p.geo),
              plan=p.estimate.as_dict(), plan_C=p.C, k=p.k,
              sequence=[r.cells for r in p.adaptation], planning_seconds=p.seconds)
    for r in rows:
        r["error_orthogonal"] = (r["error"] ** 2 + own**2) ** 0.5
        r["error_triangle"] = r["error"] + own
        r["C"] = r["error_orthogonal"] / r["eta"]
        r["C_triangle"] = r["error_triangle"] / r["eta"]
    out = {"scene": args.scene, "two_mu": two_mu, "reference_cells": L[2].num_cells(), "reference_dofs": ref.dofs,
           "reference_own_error": own, "q": q, "rows": rows, "seconds": time.perf_counter() - t0}
    path = ROOT / "benchmarks" / "results" / f"estimator_3d_{Path(args.scene).stem}.json"
    path.write_text(json.dumps(out, indent=1))
    print(f"reference own error ~ {own:.3e} (q = {q:.3f})")
    print("| run | P | cells | dofs | eta | D to the reference | error (orthogonal; triangle) | C (orthogonal; "
          "triangle) | planned C eta |")
    print("|---|---|---|---|---|---|---|---|---|")
    for r in rows:
        planned = f"{r['plan']['space_u']:.3e}" if "plan" in r else ""
        print(f"| {r['what']} | {r['degree']} | {r['cells']} | {r['dofs']} | {r['eta']:.3e} | {r['error']:.3e} | "
              f"{r['error_orthogonal']:.3e}; {r['error_triangle']:.3e} | {r['C']:.3e}; {r['C_triangle']:.3e} | "
              f"{planned} |")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
