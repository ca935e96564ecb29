"""Where in time the time error is made: how much of it a better step sequence could save (docs/model.md §3.9).

For each scene (8 x 8, order 1): the error of 80 uniform steps against a fine uniform reference (``--ref`` steps),
and of 80 uniform steps with the steps of one window of [0, T] halved, for each of ``--windows`` windows; the error
is :mod:`adaptive_work_precision`'s (max over t = 0.1, ..., 1 of the paper's norm). A window's reduction d_i
measures the error the steps there make: a first-order scheme's local error c(t) k^2 summed over a run of N steps
is smallest, N·error = (∫ c^(1/2) dt)^2, with k ~ c^(-1/2) (an equal error per step); uniform steps give T ∫ c dt.
With c ~ d_i the best step sequence takes (mean d_i^(1/2))^2 / mean d_i of the uniform run's steps for the same
error: below 1/2 only where the error is made in a small part of [0, T].

    python scripts/adaptive_error_density.py [--scenes example1 hard load_cycle] [--ref 2560] [--windows 10]

writes benchmarks/results/adaptive_error_density.md.
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))
sys.path.insert(0, str(ROOT / "scripts"))

import adaptive_work_precision as awp  # noqa: E402
from mpi4py import MPI  # noqa: E402

from solver.config import load  # noqa: E402
from solver.run.model import build_model  # noqa: E402
from solver.run.stepper import levels  # noqa: E402

BASE = 80


def run_times(scene: str, times: list[float]) -> dict:
    """A run with the given level times (variable steps), its fields at awp.CHECK."""
    file, base = awp.SCENES[scene]
    cfg = load(ROOT / "configs" / file, [*base, f"time.k={1.0 / BASE}"])
    model = build_model(cfg, MPI.COMM_WORLD)
    at = {}
    for row in levels(model, times=times):
        near = [c for c in awp.CHECK if abs(row["t"] - c) <= 1e-9]
        if near:
            z = model.damage.zeta.x.array.copy() if model.damage is not None else None
            at[near[0]] = (model.u.x.array.copy(), z)
    return {"at": at}


def density(scene: str, ref_steps: int, windows: int) -> dict:
    ref = awp.one_run(scene, [f"time.k={1.0 / ref_steps}"])
    grid = [i / BASE for i in range(BASE + 1)]
    e80 = awp.error(ref, run_times(scene, grid))
    e160 = awp.error(ref, run_times(scene, [i / (2 * BASE) for i in range(2 * BASE + 1)]))
    rows = []
    for w in range(windows):
        a, b = w / windows, (w + 1) / windows
        half = [a + (b - a) * i / (2 * BASE // windows) for i in range(2 * BASE // windows + 1)]
        times = sorted({round(t, 12) for t in grid + half})
        rows.append({"window": [a, b], "error": awp.error(ref, run_times(scene, times))})
    d = np.maximum([e80 - r["error"] for r in rows], 0.0)
    best = float(np.mean(np.sqrt(d)) ** 2 / np.mean(d)) if d.sum() > 0 else float("nan")
    return {"e80": e80, "e160": e160, "windows": rows, "best_ratio": best}


def markdown(data: dict, args: argparse.Namespace) -> str:
    lines = ["# Where the time error is made", "",
             f"`python scripts/adaptive_error_density.py --scenes {' '.join(args.scenes)} --ref {args.ref} "
             f"--windows {args.windows}` (8 x 8, order 1; error: max over t = 0.1, ..., 1 of the paper's norm "
             f"against {args.ref} uniform steps). Each row: {BASE} uniform steps with the steps of one window "
             "halved, and the error that saves. Best ratio: (mean d^(1/2))^2 / mean d, the steps the best step "
             "sequence takes over the uniform run's for the same error (first order, c(t) ~ the window's saving d).",
             ""]
    for scene, r in data.items():
        lines += [f"## {scene}", "", f"{BASE} uniform steps: error {r['e80']:.3g}; {2 * BASE}: {r['e160']:.3g}. "
                  f"**Best ratio {r['best_ratio']:.2f}.**", "", "| window | error | saved |", "|---|---|---|"]
        for w in r["windows"]:
            lines.append(f"| [{w['window'][0]:.2f}, {w['window'][1]:.2f}] | {w['error']:.4g} | "
                         f"{r['e80'] - w['error']:.3g} |")
        lines.append("")
    return "\n".join(lines)


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--scenes", nargs="+", default=list(awp.SCENES), choices=list(awp.SCENES))
    p.add_argument("--ref", type=int, default=2560)
    p.add_argument("--windows", type=int, default=10)
    args = p.parse_args()
    data = {}
    for scene in args.scenes:
        data[scene] = density(scene, args.ref, args.windows)
        (ROOT / "benchmarks/results/adaptive_error_density.md").write_text(markdown(data, args))
        print(markdown({scene: data[scene]}, args), flush=True)


if __name__ == "__main__":
    main()
