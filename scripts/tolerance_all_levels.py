"""The tolerance study's reliability judged at every level of each plan (``python scripts/tolerance_all_levels.py``).

``study tolerance`` and ``tolerance_recheck.py`` judge a plan against a reference at 4x smaller step than the
reference's own plan, and compare the levels both runs have: where the steps do not divide (T/10 against T/212),
that is t = 0, T/2 and T only. Here each scene's plans are made first, and the reference (a P2 tolerance run at
REF_TOL, studies/tolerance.py's Reference) takes the step T/N with N the smallest multiple of the plans' step counts'
least common multiple that is at least 4x the reference plan's: every level of every plan is a level of the
reference. The error: max over all levels of ||eps(u - u_ref)|| + ||zeta - zeta_ref|| (PointwiseError). No cost is
measured here (the study's is).

    python scripts/tolerance_all_levels.py [--scenes ...] [--tols 1e-2 3e-3 1e-3] [--ref-tol 1e-4]
        [--scene-ref-tol example2=3e-4] [--output benchmarks/results/tolerance_all_levels.md]
"""

from __future__ import annotations

import argparse
import gc
import math
import sys
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT))


def steps_of(T: float, k: float) -> int:
    """T / k as the integer it is (a plan's uniform step divides T)."""
    n = round(T / k)
    if abs(n * k - T) > 1e-9 * T:
        raise ValueError(f"the step {k} does not divide T = {T}")
    return n


def main() -> int:
    from mpi4py import MPI

    from solver.run import formcache
    from solver.run.accuracy import plan
    from solver.run.model import build_model
    from studies.tolerance import MAX_DOFS, SCENES, Reference, quiet, scene, scene_ref_tol

    ap = argparse.ArgumentParser()
    ap.add_argument("--scenes", nargs="+", default=["example1", "example1-mu1e-3", "example3", "example2",
                                                    "example1-gap0.02"], choices=sorted(SCENES))
    ap.add_argument("--tols", nargs="+", type=float, default=[1e-2, 3e-3, 1e-3])
    ap.add_argument("--ref-tol", type=float, default=1e-4)
    ap.add_argument("--scene-ref-tol", nargs="+", default=None, type=scene_ref_tol,
                    help="NAME=TOL: a scene's own reference tolerance (default: example2=3e-4, as in the study)")
    ap.add_argument("--output", default=str(ROOT / "benchmarks" / "results" / "tolerance_all_levels.md"))
    args = ap.parse_args()
    formcache.install()
    own = dict(args.scene_ref_tol if args.scene_ref_tol is not None else [scene_ref_tol("example2=3e-4")])
    rows, refs, ok = [], [], 0
    for name in args.scenes:
        cfg = scene(name)
        T = cfg.time.T
        plans = {}
        for tol in args.tols:
            t0 = time.perf_counter()
            at_tol = cfg.replace({"accuracy": {"tolerance": tol, "max_dofs": MAX_DOFS}}, label=f"TOL {tol:g}")
            plans[tol] = (plan(at_tol, MPI.COMM_SELF, log=lambda *a: None), time.perf_counter() - t0)
        ref_tol = own.get(name, args.ref_tol)
        acc = {"accuracy": {"tolerance": ref_tol, "degrees": [2], "max_dofs": MAX_DOFS}}
        pref = plan(quiet(cfg).replace(acc, label="reference"), MPI.COMM_SELF, log=lambda *a: None)
        common = math.lcm(*(steps_of(T, p.k) for p, _ in plans.values()))
        n = common * math.ceil(4 * steps_of(T, pref.k) / common)
        ref = Reference(cfg, pref.changes, T / n, pref.geo, f"TOL {ref_tol:g}, P2 order {pref.order}",
                        pref.estimate.total)
        refs.append(f"| {name} | {ref_tol:g} | {ref.cells} | {ref.dofs} | T/{round(T / ref.k)} | {ref.estimate:.2e} | "
                    f"{ref.seconds:.0f} |")
        for tol, (p, seconds) in plans.items():
            model = build_model(quiet(p.config), MPI.COMM_SELF, p.geo)
            p.warm_start(model)
            rec = ref.measure(model)
            ok += rec["error"] <= tol
            rows.append(f"| {name} | {tol:g} | P{p.degree} o{p.order} T/{steps_of(T, p.k)}, {p.geo.num_cells()} cells "
                        f"| {rec['levels']} of {steps_of(T, p.k) + 1} | {rec['error']:.3e} | **{rec['error'] / tol:.2f}** "
                        f"| {rec['t_max']:g} | {rec['error_u']:.2e}; {rec['error_zeta']:.2e} | {ref_tol / tol:.2f} "
                        f"| {p.estimate.total:.3e} | {seconds:.1f} |")
            print(rows[-1], flush=True)
            del model
        del plans, ref, pref
        gc.collect()
    lines = ["# The tolerance study's plans judged at every level (`python scripts/tolerance_all_levels.py`)", "",
             "Each plan against a P2 tolerance run at the reference TOL whose step T/N has every level of every plan of "
             "the scene (N a multiple of the plans' step counts, at least 4x the reference plan's); error = max over "
             "all levels of ||eps(u - u_ref)|| + ||zeta - zeta_ref|| (studies/reference.py's PointwiseError). The "
             "reference's own error: about its estimate (a tolerance plan's), not bounded here. Planning seconds on a "
             "shared, loaded 2-core machine.", "",
             "| scene | TOL | plan | levels judged | error | error / TOL | worst t | u; zeta | reference TOL / TOL "
             "| estimate | planning (s) |", "|---|---|---|---|---|---|---|---|---|---|---|", *rows, "",
             f"Within TOL: {ok} of {len(rows)}.", "",
             "References:", "", "| scene | TOL | cells | dofs | k | its estimate | seconds |",
             "|---|---|---|---|---|---|---|", *refs]
    Path(args.output).write_text("\n".join(lines) + "\n")
    print("\n".join(lines))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
