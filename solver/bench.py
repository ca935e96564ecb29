"""Benchmark of the time loop: time per step against a floor measured in the same run.

``python -m solver bench`` runs Example 1 (k = 0.01, 100 steps) at several n, each case
in its own process (so peak memory is per case), serially and under ``mpirun -n 2``,
then the reference run of the convergence study (n = 256, k = 0.0005, 2000 steps) and
the memory-flatness check for the constant and exponential kernels. It writes
``bench.json`` and ``bench.md``.

The floor is what any implementation of the scheme must pay per step: one triangular
solve pair of the factored displacement matrix, one of the damage matrix, and one
assembly of the two right-hand sides, timed (median of 20) on the run's own objects.
"""

from __future__ import annotations

import argparse
import json
import os
import resource
import subprocess
import sys
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
EXAMPLE1 = ROOT / "configs" / "example1.toml"
PHASES = ("time_damage", "time_memory", "time_displacement", "time_diagnostics", "time_output")


def _median_time(fn, comm, reps: int = 20) -> float:
    fn()
    ts = []
    for _ in range(reps):
        comm.barrier()
        t0 = time.perf_counter()
        fn()
        comm.barrier()
        ts.append(time.perf_counter() - t0)
    return float(np.median(ts))


def run_case(n: int, k: float, T: float, kernel: str = "constant") -> dict:
    """One benchmark case in this process; returns its figures (same on every rank)."""
    from mpi4py import MPI

    from .config import load
    from .stepper import build_model, run

    comm = MPI.COMM_WORLD
    sets = [f"mesh.nx={n}", f"mesh.ny={n}", f"time.k={k}", f"time.T={T}", "output.xdmf=false"]
    if kernel == "exponential":
        sets += ["memory.kernel='exponential'", "memory.weights=[-1.0]", "memory.times=[1.0]"]
    cfg = load(EXAMPLE1, sets)
    t0 = time.perf_counter()
    model = build_model(cfg, comm)
    t_build = time.perf_counter() - t0
    t0 = time.perf_counter()
    rows = run(model)
    t_run = time.perf_counter() - t0
    steady = rows[1:]  # level 0 holds the first factorizations

    mech, dmg = model.mech, model.damage
    ksp = mech.solver.snes.getKSP()
    ops = mech.ops
    x = ops.b.duplicate()
    floor = {
        "solve_displacement": _median_time(lambda: ksp.solve(ops.b, x), comm),
        "solve_damage": _median_time(lambda: dmg.ksp.solve(dmg.b, dmg.x), comm),
        "assemble_rhs": _median_time(lambda: (ops.assemble_rhs(T), dmg.assemble_rhs()), comm),
    }
    floor["total"] = sum(floor.values())
    split = {p: float(np.median([r[p] for r in steady])) for p in PHASES}
    step = float(np.median([r["wall_time"] for r in steady]))
    peak = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024.0  # MiB
    return {
        "n": n, "k": k, "steps": cfg.time.steps, "kernel": kernel, "nproc": comm.size,
        "dofs_u": mech.u.function_space.dofmap.index_map.size_global * 2,
        "dofs_zeta": dmg.V.dofmap.index_map.size_global,
        "build_s": t_build, "run_s": t_run, "level0_s": rows[0]["wall_time"],
        "step_ms": 1e3 * step, "split_ms": {p.removeprefix("time_"): 1e3 * v for p, v in split.items()},
        "newton_per_step": float(np.mean([r["newton_iterations"] for r in steady])),
        "factorizations_per_step": float(np.mean([r["factorizations"] for r in steady])),
        "factorizations_total": int(sum(r["factorizations"] for r in rows)),
        "floor_ms": {key: 1e3 * v for key, v in floor.items()},
        "ratio": step / floor["total"],
        "peak_mib_max": comm.allreduce(peak, op=MPI.MAX),
        "peak_mib_sum": comm.allreduce(peak, op=MPI.SUM),
        "final": {key: rows[-1][key] for key in ("contact_force", "zeta_min", "strain_norm", "zeta_norm")},
    }


def _spawn(n: int, k: float, T: float, kernel: str, nproc: int) -> dict:
    env = dict(os.environ, OMPI_ALLOW_RUN_AS_ROOT="1", OMPI_ALLOW_RUN_AS_ROOT_CONFIRM="1")
    cmd = [sys.executable, "-m", "solver.bench", "case", str(n), str(k), str(T), kernel]
    if nproc > 1:
        cmd = ["mpirun", "-n", str(nproc), "--oversubscribe", *cmd]
    res = subprocess.run(cmd, capture_output=True, text=True, env=env, cwd=ROOT)
    if res.returncode != 0:
        raise RuntimeError(f"benchmark case n={n} k={k} np={nproc} failed:\n{res.stderr[-2000:]}")
    return json.loads(res.stdout.strip().splitlines()[-1])


def _table(results: dict) -> str:
    lines = [
        "| n | ranks | u dofs | step (ms) | damage | memory | displacement | diagnostics | output | floor (ms) "
        "| step / floor | Newton/step | factorizations/step | peak MiB (max rank) |",
        "|---|---|---|---|---|---|---|---|---|---|---|---|---|---|",
    ]
    for c in results["sizes"]:
        s = c["split_ms"]
        lines.append(
            f"| {c['n']} | {c['nproc']} | {c['dofs_u']} | {c['step_ms']:.2f} | {s['damage']:.2f} | {s['memory']:.2f} "
            f"| {s['displacement']:.2f} | {s.get('diagnostics', float('nan')):.2f} | {s['output']:.2f} "
            f"| {c['floor_ms']['total']:.2f} | {c['ratio']:.2f} "
            f"| {c['newton_per_step']:.2f} | {c['factorizations_per_step']:.3f} | {c['peak_mib_max']:.0f} |"
        )
    out = ["## Time per step (Example 1, k = 0.01, 100 steps; medians over steps 1-100)", "", *lines, ""]
    out += ["Floor = displacement solve + damage solve + assembly of both right-hand sides (medians of 20, same run).", ""]
    sp = results.get("speedup", {})
    if sp:
        out += ["## mpirun -n 2 against one process (time per step)", "", "| n | 1 rank (ms) | 2 ranks (ms) | speed-up "
                "| max field difference |", "|---|---|---|---|---|"]
        for n, v in sp.items():
            out.append(f"| {n} | {v['serial_ms']:.2f} | {v['parallel_ms']:.2f} | {v['speedup']:.2f} | {v['max_diff']:.1e} |")
        out.append("")
    ref = results.get("reference")
    if ref:
        out += ["## Reference run of the convergence study (n = 256, k = 0.0005, 2000 steps, one process)", "",
                f"- total {ref['build_s'] + ref['run_s']:.1f} s (set-up {ref['build_s']:.1f} s, level 0 "
                f"{ref['level0_s']:.1f} s, {ref['step_ms']:.1f} ms per step, step / floor {ref['ratio']:.2f}); "
                f"peak memory {ref['peak_mib_max']:.0f} MiB", ""]
    mem = results.get("memory_flat", [])
    if mem:
        out += ["## Memory against the number of steps", "", "| kernel | n | steps | peak MiB |", "|---|---|---|---|"]
        for c in mem:
            out.append(f"| {c['kernel']} | {c['n']} | {c['steps']} | {c['peak_mib_max']:.0f} |")
        out.append("")
    return "\n".join(out)


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(prog="solver bench", description=__doc__.splitlines()[0])
    p.add_argument("--sizes", type=int, nargs="+", default=[32, 64, 128, 256])
    p.add_argument("--nproc", type=int, default=2, help="ranks for the parallel runs (0: none)")
    p.add_argument("--no-reference", action="store_true", help="skip the 2000-step reference run")
    p.add_argument("--output", default=str(ROOT / "benchmarks" / "results"))
    args = p.parse_args(argv)
    out = Path(args.output)
    out.mkdir(parents=True, exist_ok=True)
    results: dict = {"sizes": [], "speedup": {}, "memory_flat": [], "machine": os.uname().nodename,
                     "cores": os.cpu_count(), "date": time.strftime("%Y-%m-%d %H:%M")}
    for n in args.sizes:
        c = _spawn(n, 0.01, 1.0, "constant", 1)
        results["sizes"].append(c)
        print(f"n={n:4d} 1 rank : {c['step_ms']:7.2f} ms/step, floor {c['floor_ms']['total']:6.2f} ms, "
              f"ratio {c['ratio']:.2f}", flush=True)
        if args.nproc > 1:
            q = _spawn(n, 0.01, 1.0, "constant", args.nproc)
            results["sizes"].append(q)
            diff = max(abs(q["final"][key] - c["final"][key]) for key in c["final"])
            results["speedup"][n] = {"serial_ms": c["step_ms"], "parallel_ms": q["step_ms"],
                                     "speedup": c["step_ms"] / q["step_ms"], "max_diff": diff}
            print(f"n={n:4d} {args.nproc} ranks: {q['step_ms']:7.2f} ms/step, speed-up "
                  f"{c['step_ms'] / q['step_ms']:.2f}, max difference {diff:.1e}", flush=True)
    if not args.no_reference:
        ref = _spawn(256, 0.0005, 1.0, "constant", 1)
        results["reference"] = ref
        print(f"reference n=256 k=0.0005: {ref['build_s'] + ref['run_s']:.1f} s, peak {ref['peak_mib_max']:.0f} MiB",
              flush=True)
        base = next(c for c in results["sizes"] if c["n"] == 256 and c["nproc"] == 1) if 256 in args.sizes else None
        if base:
            results["memory_flat"] += [base, ref]
        for k in (0.01, 0.0005):
            results["memory_flat"].append(_spawn(128, k, 1.0, "exponential", 1))
    (out / "bench.json").write_text(json.dumps(results, indent=1))
    (out / "bench.md").write_text(_table(results))
    print(f"wrote {out / 'bench.json'} and {out / 'bench.md'}")
    return 0


if __name__ == "__main__":
    if len(sys.argv) > 1 and sys.argv[1] == "case":
        n, k, T, kernel = int(sys.argv[2]), float(sys.argv[3]), float(sys.argv[4]), sys.argv[5]
        result = run_case(n, k, T, kernel)
        from mpi4py import MPI

        if MPI.COMM_WORLD.rank == 0:
            print(json.dumps(result))
        raise SystemExit(0)
    raise SystemExit(main())
