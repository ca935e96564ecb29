"""What ``solver.contact_points = "nodes"`` does to a run's results, beside the default's own discretization error.

    python scripts/contact_points_accuracy.py [--scenes moving_contact:32 hard:48] [--refine 2]
        [--out benchmarks/results/contact_points_accuracy]

Each scene (configs/NAME.toml at P2, order 2, n x n, as benchmarks/moving_contact_iterations.py runs it) is run three
times in this process, serially: the law at the Gauss points (the default) and at the nodes on the n mesh, and at
the Gauss points on the mesh ``--refine`` times finer (nested: the n run's fields are exactly representable there).
Per run, every level's u and zeta are kept; written to OUT.md and OUT.csv:

- nodes - gauss: max over the levels of the paper's norm ||eps(u - u')|| + ||zeta - zeta'|| on the n mesh;
- each n run against the fine Gauss run (the n fields interpolated onto the fine mesh): the same norm, the
  estimate of that run's discretization error (of u and zeta: the fine run's own error is not in it);
- the contact force, peak pressure and contact length at every level: the largest difference from the fine run's,
  relative to the fine run's largest value; and the total Newton iterations.
"""

from __future__ import annotations

import argparse
import csv
import sys
import time
from pathlib import Path

import numpy as np
from mpi4py import MPI

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT))  # this checkout's solver, not an installed one

P2 = {"discretization": {"u_degree": 2, "zeta_degree": 2}, "time": {"order": 2}, "output": {"xdmf": False}}
COLUMNS = ("contact_force", "peak_pressure", "contact_length")


def run(name: str, n: int, points: str) -> dict:
    """One run of the scene: its model, every level's u, zeta and diagnostics' columns, and its time."""
    from solver.config import load
    from solver.run.model import build_model
    from solver.run.stepper import levels

    cfg = load(ROOT / "configs" / f"{name}.toml").replace(
        {**P2, "mesh": {"nx": n, "ny": n}, "solver": {"contact_points": points}}, label="contact_points_accuracy")
    start = time.perf_counter()
    model = build_model(cfg, MPI.COMM_SELF)
    out = {"model": model, "u": [], "zeta": [], "newton": 0, **{c: [] for c in COLUMNS}}
    for row in levels(model):
        out["u"].append(model.u.x.array.copy())
        out["zeta"].append(model.damage.zeta.x.array.copy() if model.damage is not None else None)
        out["newton"] += int(row["newton_iterations"])
        for c in COLUMNS:
            out[c].append(float(row[c]))
    out["seconds"] = time.perf_counter() - start
    return out


def paper_norm(fine: dict):
    """||eps(v)|| + ||z|| of arrays on the fine run's spaces."""
    from solver.run.accuracy.time_error import norms

    norm_u, norm_z = norms(fine["model"], MPI.COMM_SELF)
    return lambda du, dz: norm_u(du) + (norm_z(dz) if dz is not None else 0.0)


def onto(coarse: dict, fine: dict):
    """The coarse run's (u, zeta) arrays interpolated onto the fine run's spaces, level by level."""
    from solver.mesh.transfer import interpolation_matrix

    Vc, Vf = coarse["model"].u.function_space, fine["model"].u.function_space
    Pu = interpolation_matrix(Vc, Vf.tabulate_dof_coordinates()[:, : Vf.mesh.geometry.dim])
    Pz = None
    if coarse["model"].damage is not None:
        Zc, Zf = coarse["model"].damage.V, fine["model"].damage.V
        Pz = interpolation_matrix(Zc, Zf.tabulate_dof_coordinates()[:, : Zf.mesh.geometry.dim])
    bs = Vc.dofmap.index_map_bs
    for u, z in zip(coarse["u"], coarse["zeta"], strict=True):
        yield (Pu @ u.reshape(-1, bs)).ravel(), (Pz @ z if Pz is not None else None)


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--scenes", nargs="+", default=["moving_contact:32", "hard:48"], help="NAME:n")
    ap.add_argument("--refine", type=int, default=2, help="the reference mesh: n times this")
    ap.add_argument("--out", default=str(ROOT / "benchmarks" / "results" / "contact_points_accuracy"))
    args = ap.parse_args()
    rows = []
    for spec in args.scenes:
        name, n = spec.split(":")[0], int(spec.split(":")[1])
        runs = {p: run(name, n, p) for p in ("gauss", "nodes")}
        fine = run(name, args.refine * n, "gauss")
        norm = paper_norm(fine)
        coarse_norm = paper_norm(runs["gauss"])
        size = max(norm(u, None) for u in fine["u"])  # max over the levels of ||eps(u)|| of the fine run
        between = max(coarse_norm(a - b, None if za is None else za - zb) for a, b, za, zb in zip(
            runs["nodes"]["u"], runs["gauss"]["u"], runs["nodes"]["zeta"], runs["gauss"]["zeta"], strict=True))
        for points, r in runs.items():
            error = max(norm(u - uf, None if z is None else z - zf) for (u, z), uf, zf in zip(
                onto(r, fine), fine["u"], fine["zeta"], strict=True))
            row = {"scene": f"{name} P2 n={n}", "points": points, "newton": r["newton"],
                   "seconds": f"{r['seconds']:.1f}",
                   "nodes_minus_gauss": f"{between:.3e}", "against_fine": f"{error:.3e}",
                   "max_eps_u_fine": f"{size:.4e}", "fine": f"gauss n={args.refine * n}",
                   "fine_newton": fine["newton"]}
            for c in COLUMNS:
                ref = np.asarray(fine[c])
                row[f"{c}_vs_fine"] = f"{np.max(np.abs(np.asarray(r[c]) - ref)) / np.max(np.abs(ref)):.3e}"
                row[f"{c}_end"] = f"{r[c][-1]:.6g}"
            rows.append(row)
            print(row, flush=True)
    with open(f"{args.out}.csv", "w", newline="") as f:
        w = csv.DictWriter(f, list(rows[0]))
        w.writeheader()
        w.writerows(rows)
    cmd = "python scripts/contact_points_accuracy.py " + " ".join(sys.argv[1:])
    lines = [f"# The contact law at the nodes against the Gauss points: the results\n\n`{cmd.strip()}`\n",
             "Paper's norm: max over the levels of ||eps(u - u')|| + ||zeta - zeta'||. \"vs fine\": against the Gauss "
             "run on the finer mesh (the n fields interpolated exactly onto it); columns of the time series: the "
             "largest difference over the levels relative to the fine run's largest value.\n",
             "| scene | points | Newton (total) | nodes − gauss, same mesh | vs fine (paper's norm) | max ‖ε(u)‖ fine | "
             "force vs fine | peak pressure vs fine | contact length vs fine |", "|---|---|---|---|---|---|---|---|---|"]
    for r in rows:
        lines.append(f"| {r['scene']} | {r['points']} | {r['newton']} | {r['nodes_minus_gauss']} | {r['against_fine']} | "
                     f"{r['max_eps_u_fine']} | {r['contact_force_vs_fine']} | {r['peak_pressure_vs_fine']} | "
                     f"{r['contact_length_vs_fine']} |")
    Path(f"{args.out}.md").write_text("\n".join(lines) + "\n")
    print(f"wrote {args.out}.md", flush=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())
