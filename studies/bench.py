"""Benchmark of the time loop: time per step against a floor measured in the same run, and the cost of output.

``python -m studies bench`` runs Example 1 (k = 0.01, 100 steps) at several n, each case
in its own process (so peak memory is per case), serially and under ``mpirun -n 2``,
writing every level (the output column is that write, XDMF included). Then the output
cases: Example 1 at n = 32, k = 0.001 writing every level against writing none (whole run,
1 and 2 ranks, and the two runs' files compared), and n = 128, k = 0.0005 (2,000 levels)
written at every level, with the write time per level at the first and the last levels.
Then the reference run of the convergence study (n = 256, k = 0.0005, 2000 steps),
unwritten and with every 10th level written, and the memory-flatness check for the
constant and exponential kernels. It writes ``bench.json`` and ``bench.md``.

The floor is what any implementation of the scheme must pay per step: one triangular
solve pair of the factored displacement matrix, one of the damage matrix, and one
assembly of the two right-hand sides, timed (median of 20) on the run's own objects.
"""

from __future__ import annotations

import argparse
import json
import os
import resource
import shutil
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

from studies import REPO as ROOT  # noqa: E402
from studies import blas

EXAMPLE1 = ROOT / "configs" / "example1.toml"
# discretization variants of the constant-kernel case: "<space>-order<k>" (P2 at n has the dofs of P1 at 2n)
VARIANTS = {"p1-order2": ["time.order=2"], "p2-order1": ["discretization.u_degree=2"],
            "p2-order2": ["discretization.u_degree=2", "time.order=2"]}
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


def _window(rows: list[dict], steps: list[int], key: str = "time_output") -> float:
    """Median of ``key`` over the rows of the given steps (ms)."""
    picked = [r[key] for r in rows if r["step"] in set(steps)]
    return 1e3 * float(np.median(picked))


def _disk_bytes(directory: Path) -> int:
    """Bytes the results take on disk (allocated blocks: the data chunks are sparse until written)."""
    return sum(p.stat().st_blocks * 512 for p in directory.rglob("*") if p.is_file())


def run_case(n: int, k: float, T: float, kernel: str = "constant", every: int | None = None,
             outdir: str | None = None) -> dict:
    """One benchmark case in this process; returns its figures (same on every rank).

    ``every`` None: nothing is written (no directory); else the run writes to ``outdir`` with
    ``output.every = every`` and its other output settings at their defaults.
    """
    from mpi4py import MPI

    from solver.config import load
    from solver.io.results import run
    from solver.run.model import build_model
    from solver.run.stepper import writes_level

    comm = MPI.COMM_WORLD
    sets = [f"mesh.nx={n}", f"mesh.ny={n}", f"time.k={k}", f"time.T={T}"]
    sets += ["output.xdmf=false"] if every is None else [f"output.every={every}"]
    if kernel == "exponential":
        sets += ["memory.kernel='exponential'", "memory.weights=[-1.0]", "memory.times=[1.0]"]
    sets += VARIANTS.get(kernel, [])
    cfg = load(EXAMPLE1, sets)
    t0 = time.perf_counter()
    model = build_model(cfg, comm)
    t_build = time.perf_counter() - t0
    directory = Path(outdir) if every is not None else None
    if directory is not None and comm.rank == 0:
        directory.mkdir(parents=True, exist_ok=True)
    comm.barrier()
    t0 = time.perf_counter()
    rows = run(model, directory)
    t_run = time.perf_counter() - t0
    steady = rows[1:]  # level 0 holds the first factorizations
    steps = cfg.time.steps
    output = None
    if every is not None:
        written = [r["step"] for r in rows if writes_level(r["step"], steps, every)]
        output = {"every": every, "levels": len(written), "fields": list(cfg.output.fields),
                  "disk_bytes": _disk_bytes(directory) if comm.rank == 0 else 0}
        if len(written) > 16:  # the write time per level around the 10th written level and over the last 11
            first, last = written[5:16], written[-11:]
            output.update({"first_ms": _window(rows, first), "last_ms": _window(rows, last),
                           "first_step_ms": _window(rows, first, "wall_time"), "last_step_ms": _window(rows, last, "wall_time"),
                           "first_window": [first[0], first[-1]], "last_window": [last[0], last[-1]]})
        output["disk_bytes"] = comm.bcast(output["disk_bytes"], root=0)

    mech, dmg = model.mech, model.damage
    ksp = mech.solver.core.ksp  # the Newton-type methods' KSP on J
    ops = mech.ops
    x = ops.b.duplicate()
    floor = {
        "solve_displacement": _median_time(lambda: ksp.solve(ops.b, x), comm),
        "solve_damage": _median_time(lambda: dmg.ksp.solve(dmg.b, dmg.x), comm),
        "assemble_rhs": _median_time(lambda: (ops.assemble_rhs(T), dmg.assemble_rhs()), comm),
    }
    floor["total"] = sum(floor.values())
    # apart, not in the floor: one evaluation of the memory source H = zeta Phi_L(A eps(u)) at the memory points,
    # which the scheme needs once per step (the history of level n-1) whatever the implementation
    source = model.history.H if model.history is not None else None
    if source is not None:
        h = np.empty_like(model.history.M.x.array)
        forget = getattr(source, "forget", lambda: None)
        floor["memory_source"] = _median_time(lambda: (forget(), source(h)), comm)
    split = {p: float(np.median([r[p] for r in steady])) for p in PHASES}
    step = float(np.median([r["wall_time"] - r["time_output"] for r in steady]))  # the output is reported apart
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
        "ratio_with_source": step / (floor["total"] + floor.get("memory_source", 0.0)),
        "peak_mib_max": comm.allreduce(peak, op=MPI.MAX),
        "peak_mib_sum": comm.allreduce(peak, op=MPI.SUM),
        "final": {key: rows[-1][key] for key in ("contact_force", "zeta_min", "strain_norm", "zeta_norm")},
        "output": output,
    }


def _spawn(n: int, k: float, T: float, kernel: str, nproc: int, every: int | None = None,
           outdir: Path | None = None) -> dict:
    env = dict(os.environ, OMPI_ALLOW_RUN_AS_ROOT="1", OMPI_ALLOW_RUN_AS_ROOT_CONFIRM="1")
    cmd = [sys.executable, "-m", "studies.bench", "case", str(n), str(k), str(T), kernel]
    if every is not None:
        cmd += [str(every), str(outdir)]
    if nproc > 1:
        cmd = ["mpirun", "-n", str(nproc), "--oversubscribe", *cmd]
    res = subprocess.run(cmd, capture_output=True, text=True, env=env, cwd=ROOT)
    if res.returncode != 0:
        raise RuntimeError(f"benchmark case n={n} k={k} np={nproc} failed:\n{res.stderr[-2000:]}")
    return json.loads(res.stdout.strip().splitlines()[-1])


def _table(results: dict) -> str:
    lines = [
        "| n | ranks | u dofs | step (ms) | damage | memory | displacement | diagnostics | floor (ms) "
        "| step / floor | output (ms) | Newton/step | factorizations/step | peak MiB (max rank) |",
        "|---|---|---|---|---|---|---|---|---|---|---|---|---|---|",
    ]
    for c in results["sizes"]:
        s = c["split_ms"]
        lines.append(
            f"| {c['n']} | {c['nproc']} | {c['dofs_u']} | {c['step_ms']:.2f} | {s['damage']:.2f} | {s['memory']:.2f} "
            f"| {s['displacement']:.2f} | {s.get('diagnostics', float('nan')):.2f} "
            f"| {c['floor_ms']['total']:.2f} | {c['ratio']:.2f} | {s['output']:.2f} "
            f"| {c['newton_per_step']:.2f} | {c['factorizations_per_step']:.3f} | {c['peak_mib_max']:.0f} |"
        )
    out = [blas.report_line(results.get("blas")), "",
           "## Time per step (Example 1, k = 0.01, 100 steps; medians over steps 1-100)", "", *lines, ""]
    out += ["Floor = displacement solve + damage solve + assembly of both right-hand sides (medians of 20, same run). "
            "Step = the step without its output; output = writing the level (default fields, XDMF included), "
            "every level written.", ""]
    o = results.get("output", {})
    if o:
        out += ["## Output: Example 1, n = 32, k = 0.001 (1,001 levels), every level written against none", "",
                "| ranks | whole run, every = 1 (s) | every = 0 (s) | ratio | write per level, levels 5-15 (ms) "
                "| levels 990-1000 (ms) | on disk (MiB) |", "|---|---|---|---|---|---|---|"]
        for key in sorted(k for k in o if k.startswith("n32_np")):
            w, z = o[key]["written"], o[key]["unwritten"]
            out.append(f"| {w['nproc']} | {w['build_s'] + w['run_s']:.2f} | {z['build_s'] + z['run_s']:.2f} "
                       f"| {o[key]['ratio']:.2f} | {w['output']['first_ms']:.3f} | {w['output']['last_ms']:.3f} "
                       f"| {w['output']['disk_bytes'] / 2**20:.0f} |")
        out.append("")
        out += ["Whole run = set-up + time loop; medians of alternated pairs (written, unwritten), each pair's "
                "totals: " + "; ".join(f"{o[key]['written']['nproc']} rank(s) "
                                       + ", ".join(f"{a:.2f}/{b:.2f}" for a, b in o[key].get("totals", []))
                                       for key in sorted(k for k in o if k.startswith("n32_np"))) + " s.", ""]
        if "n32_serial_vs_parallel" in o:
            out += [f"Largest difference between the fields written by 1 and 2 ranks (every level): "
                    f"{o['n32_serial_vs_parallel']:.1e}.", ""]
        if "n128" in o:
            c = o["n128"]["output"]
            ratios = o["n128"].get("step_ratios", [])
            out += ["## Output: n = 128, k = 0.0005 (2,001 levels), every level written", "",
                    f"- write per level (median, the median run): {c['first_ms']:.2f} ms at levels "
                    f"{_span(c['first_window'])}, {c['last_ms']:.2f} ms at levels {_span(c['last_window'])}; the whole "
                    f"step {c['first_step_ms']:.2f} -> {c['last_step_ms']:.2f} ms; {c['disk_bytes'] / 2**20:.0f} MiB on disk",
                    f"- the whole step at levels {_span(c['last_window'])} over levels {_span(c['first_window'])}, "
                    f"{len(ratios)} runs: {', '.join(f'{r:.2f}' for r in ratios)} (median "
                    f"{o['n128'].get('step_ratio', float('nan')):.2f})", ""]
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
        r10 = results.get("reference_every10")
        if r10:
            pairs = ", ".join(f"{a:.1f}/{b:.1f}" for a, b in r10.get("totals", []))
            out += [f"- with every 10th level written: {r10['ratio']:.2f}x the unwritten run (medians of two alternated "
                    f"pairs, written/unwritten: {pairs} s; {r10['output']['disk_bytes'] / 2**20:.0f} MiB on disk)", ""]
    disc = results.get("discretizations", [])
    if disc:
        out += ["## Discretizations (Example 1, k = 0.01, 100 steps, one process, nothing written)", "",
                "| case | n | u dofs | step (ms) | damage | memory | displacement | floor (ms) | step / floor "
                "| one memory source (ms) | step / (floor + source) |",
                "|---|---|---|---|---|---|---|---|---|---|---|"]
        for c in disc:
            s = c["split_ms"]
            src = c["floor_ms"].get("memory_source", float("nan"))
            out.append(f"| {c['kernel']} | {c['n']} | {c['dofs_u']} | {c['step_ms']:.2f} | {s['damage']:.2f} "
                       f"| {s['memory']:.2f} | {s['displacement']:.2f} | {c['floor_ms']['total']:.2f} | {c['ratio']:.2f} "
                       f"| {src:.2f} | {c.get('ratio_with_source', float('nan')):.2f} |")
        out.append("")
        out += ["Step / (floor + source): the floor plus one evaluation of the memory source zeta Phi_L(A eps(u)) at the "
                "memory points, which the scheme needs once per step; reported apart, the floor is unchanged.", ""]
    mem = results.get("memory_flat", [])
    if mem:
        out += ["## Memory against the number of steps", "", "| kernel | n | steps | peak MiB |", "|---|---|---|---|"]
        for c in mem:
            out.append(f"| {c['kernel']} | {c['n']} | {c['steps']} | {c['peak_mib_max']:.0f} |")
        out.append("")
    return "\n".join(out)


def _max_difference(a_dir: Path, b_dir: Path) -> float:
    """Largest difference between two runs' written fields, over every level (inf if the levels differ)."""
    from solver.post.results import read_results

    a, b = read_results(a_dir), read_results(b_dir)
    if a["times"] != b["times"] or set(a["fields"]) != set(b["fields"]):
        return float("inf")
    return max(float(np.abs(a["fields"][f][t] - b["fields"][f][t]).max()) for f in a["fields"] for t in a["times"])


def _span(window: list[int]) -> str:
    return f"{window[0]}-{window[1]}"


OUTPUT_REPEATS = 3  # alternated written/unwritten pairs of the n = 32 output case


def _median_case(cases: list[dict]) -> dict:
    """The case whose whole run (set-up + time loop) is the median of ``cases``."""
    ordered = sorted(cases, key=lambda c: c["build_s"] + c["run_s"])
    return ordered[len(ordered) // 2]


def _output_cases(results: dict, tmp: Path, nproc: int) -> None:
    """Example 1, n = 32, k = 0.001: every level written against none (1 and ``nproc`` ranks); n = 128, 2000 levels."""
    out = results["output"]
    for ranks in [1] + ([nproc] if nproc > 1 else []):
        # runs of about 1 s on a shared machine vary by +-30%: pairs alternated, the medians compared
        pairs = [(_spawn(32, 0.001, 1.0, "constant", ranks, 1, tmp / f"n32-np{ranks}"),
                  _spawn(32, 0.001, 1.0, "constant", ranks, 0, tmp / f"n32-np{ranks}-every0"))
                 for _ in range(OUTPUT_REPEATS)]
        totals = [[c["build_s"] + c["run_s"] for c in pair] for pair in pairs]
        written, unwritten = (_median_case([pair[i] for pair in pairs]) for i in (0, 1))
        whole = (written["build_s"] + written["run_s"]) / (unwritten["build_s"] + unwritten["run_s"])
        out[f"n32_np{ranks}"] = {"written": written, "unwritten": unwritten, "ratio": whole,
                                 "totals": totals}
        w = written["output"]
        print(f"output n=32 k=0.001 {ranks} rank(s), medians of {OUTPUT_REPEATS} alternated pairs "
              f"({', '.join(f'{a:.2f}/{b:.2f}' for a, b in totals)} s): every=1 "
              f"{written['build_s'] + written['run_s']:.2f} s, every=0 "
              f"{unwritten['build_s'] + unwritten['run_s']:.2f} s, ratio {whole:.2f}; write per level "
              f"{w['first_ms']:.3f} ms at levels {_span(w['first_window'])}, {w['last_ms']:.3f} ms at levels "
              f"{_span(w['last_window'])}", flush=True)
    if nproc > 1:
        out["n32_serial_vs_parallel"] = _max_difference(tmp / "n32-np1", tmp / f"n32-np{nproc}")
        print(f"output n=32: largest difference of the written fields, 1 vs {nproc} ranks: "
              f"{out['n32_serial_vs_parallel']:.1e}", flush=True)
    for d in tmp.iterdir():
        shutil.rmtree(d)
    runs = []
    for _ in range(OUTPUT_REPEATS):  # one 25-s run can meet a burst of the machine's other work in either window
        runs.append(_spawn(128, 0.0005, 1.0, "constant", 1, 1, tmp / "n128"))
        shutil.rmtree(tmp / "n128")
        o = runs[-1]["output"]
        print(f"output n=128 k=0.0005 ({o['levels']} levels): write per level {o['first_ms']:.2f} ms at levels "
              f"{_span(o['first_window'])}, {o['last_ms']:.2f} ms at levels {_span(o['last_window'])} "
              f"(ratio {o['last_ms'] / o['first_ms']:.2f});"
              f" step with output {o['first_step_ms']:.2f} -> {o['last_step_ms']:.2f} ms (ratio "
              f"{o['last_step_ms'] / o['first_step_ms']:.2f}); {o['disk_bytes'] / 2**20:.0f} MiB", flush=True)
    ratios = sorted(r["output"]["last_step_ms"] / r["output"]["first_step_ms"] for r in runs)
    out["n128"] = dict(_median_case(runs), step_ratios=ratios, step_ratio=float(np.median(ratios)))
    print(f"output n=128: the whole step at the last levels against levels 5-15, over {len(runs)} runs: "
          f"{', '.join(f'{r:.2f}' for r in ratios)} (median {np.median(ratios):.2f})", flush=True)


def main(argv: list[str] | None = None) -> int:
    argv = sys.argv[1:] if argv is None else list(argv)
    if "--scaling" in argv:  # the 3-D scaling benchmark (studies/scaling.py), its own options
        from studies.scaling import main as scaling_main

        return scaling_main([a for a in argv if a != "--scaling"])
    if "--blas" in argv:  # the same work on several BLAS libraries (studies/blas.py), its own options
        return blas.main(["compare", *[a for a in argv if a != "--blas"]])
    p = argparse.ArgumentParser(prog="python -m studies bench", description=__doc__.splitlines()[0],
                                epilog="python -m studies bench --scaling --help: the 3-D scaling benchmark; "
                                       "python -m studies bench --blas --help: BLAS against BLAS")
    p.add_argument("--sizes", type=int, nargs="*", default=[32, 64, 128, 256], help="n of the size cases (none: skip them)")
    p.add_argument("--nproc", type=int, default=2, help="ranks for the parallel runs (0: none)")
    p.add_argument("--no-reference", action="store_true", help="skip the 2000-step reference runs")
    p.add_argument("--no-discretizations", action="store_true", help="skip the P2 / second-order cases")
    p.add_argument("--no-output", action="store_true", help="skip the output cases (n = 32 and the 2000-level n = 128)")
    p.add_argument("--output", default=str(ROOT / "benchmarks" / "results"))
    p.add_argument(blas.ALLOW_FLAG, action="store_true", help="measure even on netlib's reference BLAS (named in the report)")
    args = p.parse_args(argv)
    lib = blas.detect()  # the cases are spawned with this environment, so they load the same library
    print(f"BLAS: {lib.label()}", flush=True)
    if not blas.require_optimized(lib, args.allow_reference_blas, "python -m studies bench"):
        return 2
    out = Path(args.output)
    out.mkdir(parents=True, exist_ok=True)
    results: dict = {"sizes": [], "speedup": {}, "memory_flat": [], "output": {}, "machine": os.uname().nodename,
                     "cores": os.cpu_count(), "date": time.strftime("%Y-%m-%d %H:%M"), "blas": lib.as_dict()}
    tmp = Path(tempfile.mkdtemp(prefix=".bench-", dir=out))  # the cases' results, on the disk results go to
    try:
        for n in args.sizes:
            c = _spawn(n, 0.01, 1.0, "constant", 1, 1, tmp / f"size{n}")
            results["sizes"].append(c)
            print(f"n={n:4d} 1 rank : {c['step_ms']:7.2f} ms/step, floor {c['floor_ms']['total']:6.2f} ms, "
                  f"ratio {c['ratio']:.2f}, output {c['split_ms']['output']:.2f} ms", flush=True)
            if args.nproc > 1:
                q = _spawn(n, 0.01, 1.0, "constant", args.nproc, 1, tmp / f"size{n}-np{args.nproc}")
                results["sizes"].append(q)
                diff = max(abs(q["final"][key] - c["final"][key]) for key in c["final"])
                results["speedup"][n] = {"serial_ms": c["step_ms"], "parallel_ms": q["step_ms"],
                                         "speedup": c["step_ms"] / q["step_ms"], "max_diff": diff}
                print(f"n={n:4d} {args.nproc} ranks: {q['step_ms']:7.2f} ms/step, speed-up "
                      f"{c['step_ms'] / q['step_ms']:.2f}, max difference {diff:.1e}", flush=True)
            for d in tmp.iterdir():
                shutil.rmtree(d)
        if not args.no_discretizations:  # P1 at n = 128 and P2 at n = 64 have the same displacement dofs
            for variant, n in (("constant", 128), ("p1-order2", 128), ("p2-order1", 64), ("p2-order2", 64)):
                c = _spawn(n, 0.01, 1.0, variant, 1)
                results.setdefault("discretizations", []).append(c)
                print(f"{variant:10s} n={n:4d}: {c['step_ms']:7.2f} ms/step, floor {c['floor_ms']['total']:6.2f} ms, "
                      f"ratio {c['ratio']:.2f} (with one memory source {c['ratio_with_source']:.2f})", flush=True)
        if not args.no_output:
            _output_cases(results, tmp, args.nproc)
        if not args.no_reference:
            ref = _spawn(256, 0.0005, 1.0, "constant", 1)
            results["reference"] = ref
            print(f"reference n=256 k=0.0005: {ref['build_s'] + ref['run_s']:.1f} s, peak {ref['peak_mib_max']:.0f} MiB",
                  flush=True)
            ref10 = _spawn(256, 0.0005, 1.0, "constant", 1, 10, tmp / "reference")
            shutil.rmtree(tmp / "reference")
            again = _spawn(256, 0.0005, 1.0, "constant", 1)  # a second pair, alternated: 80-s runs vary by 10-50% here
            again10 = _spawn(256, 0.0005, 1.0, "constant", 1, 10, tmp / "reference")
            totals = [[c["build_s"] + c["run_s"] for c in pair] for pair in ((ref10, ref), (again10, again))]
            ratio = float(np.median([a for a, _ in totals]) / np.median([b for _, b in totals]))
            results["reference_every10"] = dict(ref10, ratio=ratio, totals=totals)
            print(f"reference, every 10th level written, two alternated pairs "
                  f"({', '.join(f'{a:.1f}/{b:.1f}' for a, b in totals)} s): ratio of the medians {ratio:.2f}", flush=True)
            base = next(c for c in results["sizes"] if c["n"] == 256 and c["nproc"] == 1) if 256 in args.sizes else None
            if base:
                results["memory_flat"] += [base, ref]
            for k in (0.01, 0.0005):
                results["memory_flat"].append(_spawn(128, k, 1.0, "exponential", 1))
    finally:
        shutil.rmtree(tmp, ignore_errors=True)
    if (out / "bench.json").exists():  # the scaling benchmark's part (bench --scaling) is kept
        scaling = json.loads((out / "bench.json").read_text()).get("scaling")
        if scaling is not None:
            results["scaling"] = scaling
    (out / "bench.json").write_text(json.dumps(results, indent=1))
    if results["sizes"]:  # --sizes with none: no size cases, so no table (an empty header said nothing)
        (out / "bench.md").write_text(_table(results))
        print(f"wrote {out / 'bench.json'} and {out / 'bench.md'}")
    else:
        print(f"wrote {out / 'bench.json'} (no size cases: bench.md left as it was)")
    return 0


if __name__ == "__main__":
    if len(sys.argv) > 1 and sys.argv[1] == "case":
        n, k, T, kernel = int(sys.argv[2]), float(sys.argv[3]), float(sys.argv[4]), sys.argv[5]
        every, outdir = (int(sys.argv[6]), sys.argv[7]) if len(sys.argv) > 7 else (None, None)
        result = run_case(n, k, T, kernel, every, outdir)
        from mpi4py import MPI

        if MPI.COMM_WORLD.rank == 0:
            print(json.dumps(result))
        raise SystemExit(0)
    raise SystemExit(main())
