"""Convergence in k of a power-law kernel g(s) = c s^-alpha (memory.kernel = "power"), run as a sum of exponentials.

Example 1 (configs/example1.toml) with its constant kernel replaced by g(s) = s^-0.5, on one mesh (n = 16 by
default), for k = T/10 ... T/640, against a reference with a much smaller step (T/10240) and a tighter kernel
tolerance (2e-10 instead of the default 1e-8, so more exponentials: 55 against 14-26). The error is the paper's
norm in time alone, at the coarsest run's levels (the same mesh: no space error):

    E(k) = max_n ( ||eps(u_n^ref - u_n^k)||_L2 + ||zeta_n^ref - zeta_n^k||_L2 ),

and the observed rate between successive k is log(E(k) / E(k/2)) / log 2. The reference's own error inflates the
rates of the finest k (E(k) ~ C (k^p - k_ref^p) where one term of the error leads), so a second rate solves that
relation for p from the same pair. Each run's terms and kernel error are recorded. Writes ``power_kernel.json``
and ``power_kernel.md`` to ``--output``. Runs serially, about 1.5 min.

    python scripts/power_kernel.py
"""

from __future__ import annotations

import argparse
import json
import math
import sys
import time
import tomllib
from pathlib import Path

import ufl
from dolfinx import fem
from mpi4py import MPI

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))  # this tree's solver, whichever one is installed
from solver.config import from_dict  # noqa: E402
from solver.physics.material import strain  # noqa: E402
from solver.run.model import build_model  # noqa: E402
from solver.run.stepper import levels  # noqa: E402


def run(n: int, k: float, alpha: float, coefficient: float, tolerance: float, every_t: float) -> dict:
    """One run; u and zeta kept at the times that are multiples of ``every_t``."""
    path = ROOT / "configs" / "example1.toml"
    data = tomllib.loads(path.read_text())
    data["mesh"].update(nx=n, ny=n)
    data["time"]["k"] = k
    data["memory"] = {"kernel": "power", "coefficient": coefficient, "exponent": alpha, "kernel_tolerance": tolerance,
                      "L": data["memory"]["L"]}
    cfg = from_dict(data, source=str(path), base=path.parent)
    t0 = time.perf_counter()
    model = build_model(cfg, MPI.COMM_SELF)
    stride = int(round(every_t / k))
    kept = {}
    for row in levels(model):
        if row["step"] % stride == 0:
            kept[row["step"] // stride] = (model.u.x.array.copy(), model.zeta.x.array.copy())
    fit = model.history.kernel_fit
    return {"k": k, "steps": cfg.time.steps, "terms": fit.terms, "kernel_error": fit.error, "tolerance": tolerance,
            "seconds": time.perf_counter() - t0, "model": model, "kept": kept}


def errors(ref: dict, runs: list[dict]) -> None:
    """E(k) of each run against the reference, in place."""
    model = ref["model"]
    e_u = fem.Function(model.u.function_space)
    e_z = fem.Function(model.zeta.function_space)
    energy = fem.form(ufl.inner(strain(e_u), strain(e_u)) * ufl.dx)
    mass = fem.form(e_z * e_z * ufl.dx)
    for r in runs:
        worst = 0.0
        for level, (u, z) in r["kept"].items():
            u_ref, z_ref = ref["kept"][level]
            e_u.x.array[:] = u_ref - u
            e_z.x.array[:] = z_ref - z
            worst = max(worst, math.sqrt(fem.assemble_scalar(energy)) + math.sqrt(fem.assemble_scalar(mass)))
        r["error"] = worst


def corrected_rate(k_coarse: float, k_fine: float, ratio: float, k_ref: float) -> float | None:
    """p with (k_coarse^p - k_ref^p) / (k_fine^p - k_ref^p) = ratio (None where no p in (0.01, 4) gives it)."""
    from scipy.optimize import brentq

    def f(p: float) -> float:
        return (k_coarse ** p - k_ref ** p) / (k_fine ** p - k_ref ** p) - ratio

    try:
        return brentq(f, 0.01, 4.0)
    except ValueError:
        return None


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--n", type=int, default=16)
    ap.add_argument("--alpha", type=float, default=0.5)
    ap.add_argument("--coefficient", type=float, default=1.0)
    ap.add_argument("--ks", type=int, nargs="+", default=[10, 20, 40, 80, 160, 320, 640], help="steps over T = 1")
    ap.add_argument("--ref-steps", type=int, default=10240)
    ap.add_argument("--ref-tolerance", type=float, default=2e-10)
    ap.add_argument("--tolerance", type=float, default=1e-8)
    ap.add_argument("--output", type=Path, default=ROOT / "benchmarks" / "results")
    args = ap.parse_args(argv)
    coarsest = 1.0 / min(args.ks)
    ref = run(args.n, 1.0 / args.ref_steps, args.alpha, args.coefficient, args.ref_tolerance, coarsest)
    runs = [run(args.n, 1.0 / s, args.alpha, args.coefficient, args.tolerance, coarsest) for s in args.ks]
    errors(ref, runs)
    rows = []
    for i, r in enumerate(runs):
        rate = math.log(runs[i - 1]["error"] / r["error"]) / math.log(2) if i else None
        corrected = corrected_rate(runs[i - 1]["k"], r["k"], runs[i - 1]["error"] / r["error"], ref["k"]) if i else None
        rows.append({key: r[key] for key in ("k", "steps", "terms", "kernel_error", "tolerance", "seconds", "error")}
                    | {"rate": rate, "rate_ref_corrected": corrected})
    info = {"n": args.n, "alpha": args.alpha, "coefficient": args.coefficient,
            "reference": {key: ref[key] for key in ("k", "steps", "terms", "kernel_error", "tolerance", "seconds")}}
    args.output.mkdir(parents=True, exist_ok=True)
    (args.output / "power_kernel.json").write_text(json.dumps({"info": info, "rows": rows}, indent=1) + "\n")
    rf = info["reference"]
    md = ["# Power-law kernel: convergence in k (scripts/power_kernel.py)", "",
          f"Example 1 with g(s) = {args.coefficient:g} s^-{args.alpha:g} (memory.kernel = \"power\"), n = {args.n}, "
          f"T = 1, left rule. Reference: k = 1/{rf['steps']}, kernel_tolerance {rf['tolerance']:g} "
          f"({rf['terms']} exponentials, kernel error {rf['kernel_error']:.1e}). "
          "E(k) = max_n ||eps(u_ref - u_k)|| + ||zeta_ref - zeta_k|| at the levels of k = "
          f"1/{min(args.ks)}; rate = log2(E(2k) / E(k)); corrected: p in E(k) = C (k^p - k_ref^p) from the same "
          "pair (the reference's own error taken out).", "",
          "| k | terms | kernel error | E(k) | rate | rate, corrected | run s |", "|---|---|---|---|---|---|---|"]
    for r in rows:
        rate = f"{r['rate']:.2f}" if r["rate"] is not None else "—"
        corr = f"{r['rate_ref_corrected']:.2f}" if r["rate_ref_corrected"] is not None else "—"
        md.append(f"| 1/{r['steps']} | {r['terms']} | {r['kernel_error']:.1e} | {r['error']:.3e} | {rate} | {corr} "
                  f"| {r['seconds']:.1f} |")
    (args.output / "power_kernel.md").write_text("\n".join(md) + "\n")
    print("\n".join(md))
    return 0


if __name__ == "__main__":
    sys.exit(main())
