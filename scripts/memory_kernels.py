"""Does a tabulated kernel cost what its Prony form costs? Example 1 with a two-term Prony kernel, given once as Prony
terms (``kernel = "exponential"``) and once as a table sampled from it (``kernel = "tabulated"``, which the solver
fits by a sum of exponentials at set-up), run alternately in child processes.

Each child is the command line (``python -m solver run``) under ``/usr/bin/time``: its peak resident memory (``%M``)
and its time loop (the sum of the time series' ``wall_time``). Reported: the medians and ranges over the rounds and
the ratios table / Prony of the medians, and the largest relative differences of the contact force and zeta_min over
all levels between the two (``max_n |a_n - b_n| / |b_n|``). With ``--base CHECKOUT`` the table also runs, once, on
an older tree that kept the whole past (fbee029) for the same figures. Writes ``NAME.json`` and ``NAME.md``.

    python scripts/memory_kernels.py --rounds 3                      # n = 32, 2,000 steps; n = 16, 10,000 steps
    python scripts/memory_kernels.py --base /work/base_fbee029 --cases n32_2000
"""

from __future__ import annotations

import argparse
import csv
import json
import math
import os
import statistics
import subprocess
import sys
import tempfile
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
WEIGHTS, TIMES = (2.0, 0.5), (0.2, 5.0)  # g(s) = 2 e^{-s/0.2} + 0.5 e^{-s/5}
ROWS = 4001
# name: (n, steps on T = 1, the table's kernel_tolerance; None: the default)
CASES: dict[str, tuple[int, int, float | None]] = {
    "n32_2000": (32, 2000, None),
    "n16_10000": (16, 10_000, 1e-6),
}


def g(s: float) -> float:
    return sum(c * math.exp(-s / t) for c, t in zip(WEIGHTS, TIMES))


def scene(kernel: str, tolerance: float | None) -> str:
    """Example 1's scene with its [memory] section replaced by the two-term kernel, as terms or as a table."""
    text = (ROOT / "configs" / "example1.toml").read_text()
    head, rest = text.split("[memory]", 1)
    tail = rest[rest.index("\n["):]
    if kernel == "exponential":
        memory = f"kernel = \"exponential\"\nweights = {list(WEIGHTS)}\ntimes = {list(TIMES)}\n"
    else:
        rows = ",\n".join(f"  [{s!r}, {g(s)!r}]" for s in (i / (ROWS - 1) for i in range(ROWS)))
        memory = f"kernel = \"tabulated\"\ntable = [\n{rows}\n]\n"
        if tolerance is not None:
            memory += f"kernel_tolerance = {tolerance!r}\n"
    return f"{head}[memory]\n{memory}L = 1000.0\n{tail}"


def once(tree: Path, scene_file: Path, n: int, steps: int, out: Path) -> dict:
    """One child run: time loop, peak RSS, the contact force and zeta_min of every level, the log's memory line."""
    sets = [f"mesh.nx={n}", f"mesh.ny={n}", f"time.k={1.0 / steps!r}", "output.every=0", "output.xdmf=false"]
    cmd = ["/usr/bin/time", "-f", "maxrss_kb=%M", sys.executable, "-m", "solver", "run", str(scene_file),
           "--output", str(out), "--overwrite", "--no-progress", *(a for s in sets for a in ("--set", s))]
    p = subprocess.run(cmd, env={**os.environ, "PYTHONPATH": str(tree)}, cwd=tree, capture_output=True, text=True)
    if p.returncode != 0:
        raise RuntimeError(f"{' '.join(cmd)} failed:\n{p.stderr[-2000:]}")
    rss = int(next(ln for ln in p.stderr.splitlines() if ln.startswith("maxrss_kb=")).split("=")[1])
    with (out / "timeseries.csv").open() as f:
        rows = list(csv.DictReader(f))
    memory_line = next((ln.strip() for ln in (p.stdout + p.stderr).splitlines() if "exponential term" in ln), "")
    return {"loop_s": sum(float(r["wall_time"]) for r in rows), "peak_mib": rss / 1024,
            "contact_force": [float(r["contact_force"]) for r in rows],
            "zeta_min": [float(r["zeta_min"]) for r in rows], "memory_line": memory_line}


def refusal(tree: Path, scene_file: Path, n: int, steps: int) -> str:
    """What ``solver check`` says of the scene (a refused kernel's one line, or ok)."""
    cmd = [sys.executable, "-m", "solver", "check", str(scene_file), "--set", f"mesh.nx={n}", "--set",
           f"mesh.ny={n}", "--set", f"time.k={1.0 / steps!r}"]
    p = subprocess.run(cmd, env={**os.environ, "PYTHONPATH": str(tree)}, cwd=tree, capture_output=True, text=True)
    return (p.stdout + p.stderr).strip().splitlines()[-1]


def rel_diff(a: list[float], b: list[float]) -> float:
    return max(abs(x - y) / abs(y) for x, y in zip(a, b))


def summary(runs: list[dict], key: str) -> dict:
    v = [r[key] for r in runs]
    return {"median": statistics.median(v), "min": min(v), "max": max(v), "all": v}


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--rounds", type=int, default=3)
    ap.add_argument("--cases", nargs="+", default=list(CASES), choices=list(CASES))
    ap.add_argument("--base", type=Path, help="a checkout that kept the tabulated past (fbee029): its table, once")
    ap.add_argument("--name", default="memory_kernels")
    ap.add_argument("--output", type=Path, default=ROOT / "benchmarks" / "results")
    args = ap.parse_args(argv)
    path = args.output / f"{args.name}.json"
    results = json.loads(path.read_text()) if path.exists() else {}
    with tempfile.TemporaryDirectory() as tmp:
        tmp = Path(tmp)
        for case in args.cases:
            n, steps, tol = CASES[case]
            files = {}
            for kernel in ("exponential", "tabulated"):
                files[kernel] = tmp / f"{case}_{kernel}.toml"
                files[kernel].write_text(scene(kernel, tol))
            runs: dict[str, list[dict]] = {"exponential": [], "tabulated": []}
            for r in range(args.rounds):
                for kernel in (("exponential", "tabulated") if r % 2 == 0 else ("tabulated", "exponential")):
                    runs[kernel].append(once(ROOT, files[kernel], n, steps, tmp / f"{case}_{kernel}"))
                    print(case, kernel, f"loop {runs[kernel][-1]['loop_s']:.2f} s",
                          f"peak {runs[kernel][-1]['peak_mib']:.0f} MiB", flush=True)
            res = {"n": n, "steps": steps, "rows": ROWS, "kernel_tolerance": tol if tol is not None else 1e-8,
                   "rounds": args.rounds, "memory_line": runs["tabulated"][0]["memory_line"]}
            for kernel, rs in runs.items():
                res[kernel] = {"loop_s": summary(rs, "loop_s"), "peak_mib": summary(rs, "peak_mib")}
            res["ratio_loop"] = res["tabulated"]["loop_s"]["median"] / res["exponential"]["loop_s"]["median"]
            res["ratio_peak"] = res["tabulated"]["peak_mib"]["median"] / res["exponential"]["peak_mib"]["median"]
            a, b = runs["tabulated"][0], runs["exponential"][0]
            res["rel_diff_contact_force"] = rel_diff(a["contact_force"], b["contact_force"])
            res["rel_diff_zeta_min"] = rel_diff(a["zeta_min"], b["zeta_min"])
            if tol is not None:  # the same table at the default tolerance
                files["default"] = tmp / f"{case}_default.toml"
                files["default"].write_text(scene("tabulated", None))
                res["default_tolerance"] = refusal(ROOT, files["default"], n, steps)
            if args.base is not None:
                old = once(args.base.resolve(), files["tabulated"] if tol is None else files["default"], n, steps,
                           tmp / f"{case}_base")
                pro = once(args.base.resolve(), files["exponential"], n, steps, tmp / f"{case}_base_prony")
                res["base"] = {"tree": str(args.base), "tabulated_loop_s": old["loop_s"],
                               "tabulated_peak_mib": old["peak_mib"], "exponential_loop_s": pro["loop_s"],
                               "exponential_peak_mib": pro["peak_mib"],
                               "rel_diff_contact_force_vs_this_table": rel_diff(a["contact_force"],
                                                                                old["contact_force"]),
                               "rel_diff_zeta_min_vs_this_table": rel_diff(a["zeta_min"], old["zeta_min"])}
            results[case] = res
            path.parent.mkdir(parents=True, exist_ok=True)
            path.write_text(json.dumps(results, indent=1) + "\n")
    (args.output / f"{args.name}.md").write_text(markdown(results))
    print((args.output / f"{args.name}.md").read_text())
    return 0


def markdown(results: dict) -> str:
    out = ["# A tabulated kernel against its Prony form (scripts/memory_kernels.py)", "",
           f"Example 1 (configs/example1.toml, T = 1) with g(s) = {WEIGHTS[0]} e^(-s/{TIMES[0]}) + {WEIGHTS[1]} "
           f"e^(-s/{TIMES[1]}), as Prony terms and as a {ROWS}-row table on [0, 1] (rows every 1/{ROWS - 1}); "
           f"one process each, alternated; {os.cpu_count()} cores, shared. Time loop: the sum of wall_time; peak: "
           "/usr/bin/time's maximum resident set. Medians [min, max] over the rounds; differences: "
           "max_n |table_n - prony_n| / |prony_n| over all levels.", "",
           "| case | steps | rounds | Prony loop s | table loop s | loop ratio | Prony peak MiB | table peak MiB "
           "| peak ratio | contact force diff | zeta_min diff |",
           "|---|---|---|---|---|---|---|---|---|---|---|"]
    for r in results.values():
        e, t = r["exponential"], r["tabulated"]
        out.append(f"| n = {r['n']} | {r['steps']} | {r['rounds']} | {e['loop_s']['median']:.2f} "
                   f"[{e['loop_s']['min']:.2f}, {e['loop_s']['max']:.2f}] | {t['loop_s']['median']:.2f} "
                   f"[{t['loop_s']['min']:.2f}, {t['loop_s']['max']:.2f}] | {r['ratio_loop']:.3f} "
                   f"| {e['peak_mib']['median']:.0f} | {t['peak_mib']['median']:.0f} | {r['ratio_peak']:.3f} "
                   f"| {r['rel_diff_contact_force']:.1e} | {r['rel_diff_zeta_min']:.1e} |")
    out.append("")
    for r in results.values():
        out.append(f"- n = {r['n']}, {r['steps']} steps, kernel_tolerance = {r['kernel_tolerance']:g}: "
                   f"`{r['memory_line']}`")
        if "default_tolerance" in r:
            out.append(f"  At the default 1e-8 (`solver check`): `{r['default_tolerance']}`")
        if "base" in r:
            b = r["base"]
            out.append(f"  The older tree ({b['tree']}, which kept the whole past), once: table {b['tabulated_loop_s']:.2f} s "
                       f"and {b['tabulated_peak_mib']:.0f} MiB, Prony {b['exponential_loop_s']:.2f} s and "
                       f"{b['exponential_peak_mib']:.0f} MiB (ratios {b['tabulated_loop_s'] / b['exponential_loop_s']:.2f} "
                       f"and {b['tabulated_peak_mib'] / b['exponential_peak_mib']:.2f}); its table's results against this "
                       f"tree's: contact force {b['rel_diff_contact_force_vs_this_table']:.1e}, zeta_min "
                       f"{b['rel_diff_zeta_min_vs_this_table']:.1e}.")
    return "\n".join(out) + "\n"


if __name__ == "__main__":
    sys.exit(main())
