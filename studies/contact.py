"""``python -m studies contact {bench,figure}``: the contact results of issue 29 (docs/contact.md).

- ``bench``: the time loop of a plane-strain block on a foundation whose gap is a 10^5-row table of one value
  against the same run with that value as a number (alternating A B A B, medians; the noisy machine makes
  single times meaningless), and the largest difference of their results (a constant table = the constant
  gap). Written to benchmarks/results/gap_table.{json,md}.
- ``figure``: λ_h along the bottom of the curved-obstacle scene (tests/physics/test_curved_obstacle.py) against
  its closed form p = E f(x), on three meshes: docs/figures/contact_pressure.png.
"""

from __future__ import annotations

import argparse
import json
import statistics
import sys
import time
from pathlib import Path

import numpy as np
from mpi4py import MPI

from studies import REPO as ROOT  # noqa: E402


def _bench_scene(gap, n: int, steps: int) -> dict:
    return {"mesh": {"corners": [[0.0, 0.0], [2.0, 1.0]], "nx": 2 * n, "ny": n}, "material": {"model": "plane_strain"},
            "time": {"T": steps * 0.05, "k": 0.05},
            "boundary": {"left": {"role": "clamped"}, "right": {"role": "traction", "traction": [0.0, -10.0]},
                         "bottom": {"role": "contact", "mu": 1e-8, "gap": gap}}}


def _time_loop(cfg) -> tuple[float, float, np.ndarray]:
    """(build time, time loop, u at every level) of one run (nothing written)."""
    from solver.run.model import build_model
    from solver.run.stepper import levels

    t0 = time.perf_counter()
    model = build_model(cfg, MPI.COMM_WORLD)
    t1 = time.perf_counter()
    us = [model.u.x.array.copy() for _ in levels(model)]
    return t1 - t0, time.perf_counter() - t1, np.array(us)


def bench(rows: int, n: int, steps: int, repeats: int, out: Path) -> dict:
    from solver.config import from_dict

    table = np.column_stack([np.linspace(0.0, 2.0, rows), np.full(rows, 1e-4)]).tolist()
    cfgs = {"constant gap": from_dict(_bench_scene(1e-4, n, steps)), f"{rows}-row table": from_dict(_bench_scene(table, n, steps))}
    for cfg in cfgs.values():  # compile the forms first
        _time_loop(cfg)
    times: dict[str, list] = {k: [] for k in cfgs}
    builds: dict[str, list] = {k: [] for k in cfgs}
    results = {}
    for _ in range(repeats):
        for name, cfg in cfgs.items():
            b, t, us = _time_loop(cfg)
            builds[name].append(b)
            times[name].append(t)
            results[name] = us
    a, b = (results[k] for k in cfgs)
    diff = float(np.abs(a - b).max() / np.abs(a).max())
    med = {k: statistics.median(v) for k, v in times.items()}
    names = list(cfgs)
    report = {"command": f"python -m studies contact bench --rows {rows} --n {n} --steps {steps} --repeats {repeats}",
              "cells": 2 * 2 * n * n, "steps": steps, "time_loop_s": times, "build_s": builds, "median_time_loop_s": med,
              "ratio_table_over_constant": med[names[1]] / med[names[0]], "max_rel_diff_u": diff}
    if MPI.COMM_WORLD.rank == 0:
        out.mkdir(parents=True, exist_ok=True)
        (out / "gap_table.json").write_text(json.dumps(report, indent=1) + "\n")
        (out / "gap_table.md").write_text(
            f"# A {rows}-row gap table against a constant gap\n\n`{report['command']}` ({report['cells']} cells, "
            f"{steps} steps, the time loop only; alternating runs, medians of {repeats})\n\n"
            + "".join(f"- {k}: median {med[k]:.3f} s (runs {', '.join(f'{t:.3f}' for t in times[k])}), build "
                      f"{statistics.median(builds[k]):.3f} s\n" for k in names)
            + f"\nratio table / constant: {report['ratio_table_over_constant']:.3f}; largest difference of u over all "
              f"levels: {diff:.1e} (relative)\n")
    return report


def figure(out: Path) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    sys.path.insert(0, str(ROOT / "tests" / "physics"))  # the closed form lives beside its test
    from test_curved_obstacle import A, E, exact_pressure_bottom, scene

    from solver.config import from_dict
    from solver.run.model import build_model
    from solver.run.stepper import Stepper

    fig, ax = plt.subplots(figsize=(6, 4))
    x = np.linspace(0, 1, 200)
    ax.plot(x, exact_pressure_bottom(x), "k-", lw=2, label="closed form E f(x)")
    for n, style in ((8, "o--"), (16, "s--"), (32, ".-")):
        model = build_model(from_dict(scene(n)), MPI.COMM_WORLD)
        Stepper(model).step(0)
        rows = dict(model.mech.diagnostics.traces.profile())["bottom"]
        ax.plot(rows[:, 1], rows[:, 7], style, ms=4, label=f"p_h, {n}×{n} mesh")
    ax.set_xlabel("x on the bottom")
    ax.set_ylabel("contact pressure")
    ax.set_ylim(0.0, 1.15 * E * A)
    ax.set_title("curved obstacle: the reported pressure against the closed form")
    ax.legend()
    fig.tight_layout()
    out.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(out, dpi=120)


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(prog="python -m studies contact")
    sub = p.add_subparsers(dest="what", required=True)
    b = sub.add_parser("bench")
    b.add_argument("--rows", type=int, default=100_000)
    b.add_argument("--n", type=int, default=32)
    b.add_argument("--steps", type=int, default=20)
    b.add_argument("--repeats", type=int, default=5)
    b.add_argument("--out", type=Path, default=ROOT / "benchmarks" / "results")
    f = sub.add_parser("figure")
    f.add_argument("--out", type=Path, default=ROOT / "docs" / "figures" / "contact_pressure.png")
    args = p.parse_args(argv)
    if args.what == "bench":
        print(json.dumps(bench(args.rows, args.n, args.steps, args.repeats, args.out)["median_time_loop_s"]))
    else:
        figure(args.out)
    return 0
