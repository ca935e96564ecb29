"""The achieved error of a P1 plan on a fixed mesh against P2 on the same mesh at half the step (serial).

For a plan that keeps the scene's mesh and chooses P1 (column3d at 1e-2: P1, order 2, k = 0.1, the 4,024-cell
gmsh mesh), the reference is P2 (u and zeta) on the same mesh, order 2, at k / 2: the P1 fields are P2 fields there,
so the difference is exact. Prints max over the plan's levels of ||eps(u_ref - u)|| + ||zeta_ref - zeta|| (the
paper's norm between them) and the reference's own estimated space error (C eta of its levels, the 3-D C), and
writes benchmarks/results/achieved_3d_<scene>.json.

    .venv/bin/python scripts/achieved_3d.py configs/column3d.toml 0.1
"""

from __future__ import annotations

import json
import math
import sys
import time
from pathlib import Path

from mpi4py import MPI

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from solver.config import load  # noqa: E402
from solver.mesh.geometry import build  # noqa: E402
from solver.mesh.transfer import interpolation_matrix  # noqa: E402
from solver.run.accuracy.constants import c_times_2mu  # noqa: E402
from solver.run.accuracy.scene import degrees, step, with_changes  # noqa: E402
from solver.run.accuracy.solves import pilot_run  # noqa: E402
from solver.run.accuracy.time_error import norms  # noqa: E402


def main() -> int:
    scene, k = sys.argv[1], float(sys.argv[2])
    comm = MPI.COMM_SELF
    cfg = with_changes(load(scene, ["output.xdmf=false"]), {"time": {"order": 2}})
    geo = build(comm, cfg.mesh, cfg.boundaries, cfg.dim)
    t0 = time.perf_counter()
    run = pilot_run(with_changes(cfg, degrees(1), step(k)), comm, geo)
    t1 = time.perf_counter()
    ref = pilot_run(with_changes(cfg, degrees(2), step(k / 2)), comm, geo, indicator=True)
    t2 = time.perf_counter()
    dim = geo.dim
    V, Z = ref.model.u.function_space, ref.model.damage.V
    Pu = interpolation_matrix(run.model.u.function_space, V.tabulate_dof_coordinates()[:, :dim])
    Pz = interpolation_matrix(run.model.damage.V, Z.tabulate_dof_coordinates()[:, :dim])
    norm_u, norm_z = norms(ref.model, comm)
    rows = []
    for j, t in enumerate(run.t):
        i = int(round(t / (k / 2)))
        assert math.isclose(ref.t[i], t, abs_tol=1e-12)
        eu = norm_u(ref.u[i] - (Pu @ run.u[j].reshape(-1, dim)).ravel())
        ez = norm_z(ref.zeta[i] - Pz @ run.zeta[j])
        rows.append({"t": t, "error_u": eu, "error_zeta": ez, "error": eu + ez})
    worst = max(rows, key=lambda r: r["error"])
    two_mu = cfg.material.E / (1.0 + cfg.material.nu)
    own = c_times_2mu(dim)[2] / two_mu * max(ref.indicator)
    out = {"scene": scene, "k": k, "cells": geo.num_cells(), "difference": worst, "levels": rows,
           "reference_own_space_estimate": own, "seconds": {"run": t1 - t0, "reference": t2 - t1}}
    (ROOT / "benchmarks" / "results" / f"achieved_3d_{Path(scene).stem}.json").write_text(json.dumps(out, indent=1))
    print(f"max over levels of the difference: {worst['error']:.3e} at t = {worst['t']:g} (u {worst['error_u']:.3e}, "
          f"zeta {worst['error_zeta']:.3e}); the reference's own space estimate C eta <= {own:.3e}; "
          f"seconds: run {t1 - t0:.1f}, reference {t2 - t1:.1f}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
