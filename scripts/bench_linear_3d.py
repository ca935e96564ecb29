"""PETSc's sequential Cholesky against the iterative solver on the 3-D Example 1 (configs/example1_3d.toml), one process.

    python scripts/bench_linear_3d.py [--sizes 8 16 24] [--steps 5] [--out benchmarks/results]

Each (size, solver) runs in its own process (so its peak memory is its own): the model is built
(set-up: mesh, forms, operators; the displacement's first factorization or GAMG set-up happens at
step 0, reported apart), then ``--steps`` steps of k = 0.02; per-step times are medians over steps
1..N (the damage matrix is factored at step 1, its first solve). Written: ``linear_3d.json`` and ``linear_3d.md``.
"""

from __future__ import annotations

import argparse
import json
import resource
import statistics
import subprocess
import sys
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
# 'auto' rows were measured when auto was PETSc's sequential Cholesky on one process
LABEL = {"auto": "direct (auto)", "petsc": "direct (sequential Cholesky)", "iterative": "iterative"}


def one(n: int, linear: str, steps: int) -> dict:
    """Run one (size, solver) in this process and return its figures."""
    from mpi4py import MPI

    from solver.config import load
    from solver.io.results import run
    from solver.run.model import build_model

    k = 0.02
    cfg = load(ROOT / "configs/example1_3d.toml", [f"mesh.nx={n}", f"mesh.ny={n}", f"mesh.nz={n}", f"time.k={k}",
                                                    f"time.T={k * steps}", f"solver.linear='{linear}'"])
    t0 = time.perf_counter()
    model = build_model(cfg, MPI.COMM_WORLD)
    setup = time.perf_counter() - t0
    solver = model.mech.solver
    rows = run(model, None)
    steady = rows[1:]
    return {
        "n": n, "linear": linear, "dofs": model.u.function_space.dofmap.index_map.size_global * 3,
        "setup_s": setup, "step0_s": rows[0]["time_displacement"],
        # medians: the damage matrix is factored (or Jacobi set up) at step 1, its first solve
        "displacement_per_step_s": statistics.median(r["time_displacement"] for r in steady),
        "damage_per_step_s": statistics.median(r["time_damage"] for r in steady),
        "damage_step1_s": steady[0]["time_damage"],
        "newton_per_step": sum(r["newton_iterations"] for r in steady) / len(steady),
        "krylov_total": solver.core.krylov_iterations,  # 3-D: a Newton-type method
        "newton_total": sum(r["newton_iterations"] for r in rows),
        "setups_total": sum(r["factorizations"] for r in rows),
        "contact_force_T": rows[-1]["contact_force"],
        "peak_mib": resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024,
    }


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--sizes", type=int, nargs="+", default=[8, 16, 24])
    p.add_argument("--steps", type=int, default=5)
    p.add_argument("--out", default=str(ROOT / "benchmarks/results"))
    p.add_argument("--one", nargs=2, metavar=("N", "LINEAR"), help=argparse.SUPPRESS)
    a = p.parse_args()
    if a.one:
        print(json.dumps(one(int(a.one[0]), a.one[1], a.steps)))
        return
    rows: list[dict] = []
    out = Path(a.out)
    out.mkdir(parents=True, exist_ok=True)
    for n in a.sizes:
        for linear in ("petsc", "iterative"):  # petsc: what auto was on one process when this was measured
            res = subprocess.run([sys.executable, __file__, "--one", str(n), linear, "--steps", str(a.steps)],
                                 capture_output=True, text=True, check=True, cwd=ROOT)
            rows.append(json.loads(res.stdout.strip().splitlines()[-1]))
            print(rows[-1], flush=True)
            write(rows, out)


def write(rows: list[dict], out: Path) -> None:
    """``linear_3d.json`` and the Markdown table ``linear_3d.md`` of the rows so far."""
    (out / "linear_3d.json").write_text(json.dumps(rows, indent=1) + "\n")
    lines = ["| n (dofs) | solver | set-up (s) | step 0 (s) | displacement / step (ms) | damage / step (ms) "
             "| Newton / step | Krylov its / Newton it | PC set-ups or factorizations | peak MiB |",
             "|---|---|---|---|---|---|---|---|---|---|"]
    for r in rows:
        kry = f"{r['krylov_total'] / r['newton_total']:.1f}" if r["linear"] == "iterative" else "-"
        lines.append(f"| {r['n']}³ ({r['dofs']}) | {LABEL.get(r['linear'], r['linear'])} "
                     f"| {r['setup_s']:.2f} | {r['step0_s']:.2f} | {1e3 * r['displacement_per_step_s']:.1f} "
                     f"| {1e3 * r['damage_per_step_s']:.1f} | {r['newton_per_step']:.2f} | {kry} | {r['setups_total']} "
                     f"| {r['peak_mib']:.0f} |")
    (out / "linear_3d.md").write_text("\n".join(lines) + "\n")
    print("\n".join(lines))


if __name__ == "__main__":
    main()
