"""Krylov iterations of the 3-D displacement solve against the stiffness of the contact term.

``python -m studies.krylov_contact --sizes 14 22 --mu 1e-10 1e-6 1e-3`` runs 3-D Example 1 (iterative solver,
level 0 and 10 steps of k = 0.02, nothing written) with the normal compliance mu of Gamma_C set to each value
(the scene's is 1e-10: a contact stiffness 1/mu = 1e10 against E = 100), each case in its own process, and
reports the Krylov iterations per linear solve. The plain elasticity solve of the same cube (no contact,
studies/anchor.py) takes 17-19 CG iterations at these sizes; if the iterations fall toward it as mu grows,
the stiff contact block is what costs them. ``--nullspace rigid contact`` runs each case with either
near-nullspace of the AMG: the plain rigid motions, or the rigid motions without their normal component on Gamma_C
(the solver's default, linear.rigid_body_modes), alternating, and reports the iterations and the displacement
solve's time per step of both. Written to ``krylov_contact.md`` with ``--output``.

``--amg gamg ml gamg-reuse`` runs each case (contact near-nullspace) with the solver's AMG (GAMG's smoothed
aggregation, set up anew when J changes), with Trilinos ML, and with GAMG keeping the interpolation of its first
set-up (PETSc's default, K's before the contact term): iterations, time per step and peak memory as ratios to the
solver's AMG, written to ``krylov_contact_amg.md``.
"""

from __future__ import annotations

import argparse
import json
import os
import statistics
import subprocess
import sys
from pathlib import Path

from studies import REPO as ROOT

NULLSPACES = ("rigid", "contact")
# the AMGs --amg compares, as scene options on top of the solver's defaults (linear.AMG)
AMGS = {"gamg": {}, "ml": {"mech_pc_type": "ml"}, "gamg-reuse": {"mech_pc_gamg_reuse_interpolation": "true"}}


def run_case(n: int, mu: float, nullspace: str = "contact", amg: str = "gamg") -> dict:
    """One case in this process: Krylov iterations per solve at level 0 and over the steps, the displacement
    solve's time per step (mean), the contact force, the process's peak memory."""
    import resource

    from mpi4py import MPI

    from solver.config import load
    from solver.io.results import run
    from solver.run.model import build_model

    cfg = load(ROOT / "configs" / "example1_3d.toml",
               [f"mesh.nx={n}", f"mesh.ny={n}", f"mesh.nz={n}", "time.k=0.02", "time.T=0.2", "output.xdmf=false",
                "solver.linear='iterative'", f"boundary.bottom.mu={mu!r}"]
               + [f"solver.petsc_options.{k}='{v}'" for k, v in AMGS[amg].items()])
    from solver.errors import DisplacementSolveError

    try:
        rows = run(build_model(cfg, MPI.COMM_WORLD, contact_near_nullspace=nullspace == "contact"), None)
    except DisplacementSolveError as e:  # a preconditioner that fails is a result (gamg-reuse at mu = 1e-10)
        return {"n": n, "mu": mu, "nullspace": nullspace, "amg": amg, "dofs": 3 * (n + 1) ** 3, "failed": str(e)}
    steps = rows[1:]
    return {"n": n, "mu": mu, "nullspace": nullspace, "amg": amg, "dofs": 3 * (n + 1) ** 3,
            "peak_mib": resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024.0,
            "step_s": statistics.mean(r["time_displacement"] for r in steps),  # 10 steps: one cycle of Fischer's guess
            "level0": rows[0]["krylov_iterations"] / rows[0]["linear_solves"],
            "steps": sum(r["krylov_iterations"] for r in steps) / sum(r["linear_solves"] for r in steps),
            "contact_force": rows[-1]["contact_force"]}


def run_case_apart(n: int, mu: float, nullspace: str = "contact", amg: str = "gamg") -> dict:
    """:func:`run_case` in a process of its own. Each case then starts from a fresh PETSc; and Debian's PETSc 3.18 with
    Trilinos ML (the iterative path's AMG before issue 30, ``--amg ml`` here) was seen to crash (SIGSEGV in the SNES
    solve) at the ninth 3-D iterative model built in one process, also at 0af5863 (GAMG does not); not root-caused."""
    res = subprocess.run([sys.executable, "-m", "studies.krylov_contact", "case", str(n), repr(mu), nullspace, amg],
                         capture_output=True, text=True, cwd=ROOT, env=dict(os.environ), check=True)
    return json.loads(res.stdout.strip().splitlines()[-1])


def _sizes_and_mus(cases: list[dict]) -> tuple[str, str]:
    """The --sizes and --mu values of the command that made ``cases``."""
    return (" ".join(str(n) for n in sorted({c["n"] for c in cases})),
            " ".join(repr(m) for m in sorted({c["mu"] for c in cases})))


def _failed_row(c: dict, label: str, empty: int) -> str:
    """A table row for a case whose solve failed: the reason, then ``empty`` blank cells."""
    return f"| {c['n']} | {c['dofs']:,} | {c['mu']:g} | {label} | failed: {c['failed'][:120]} " + "| " * empty + "|"


def _merge(runs: list[dict]) -> dict:
    """One case from its repeats: the first failure if any failed, else the median step and the largest peak."""
    failed = [r for r in runs if "failed" in r]
    if failed:
        return failed[0]
    return {**runs[0], "step_s": statistics.median(r["step_s"] for r in runs),
            "peak_mib": max(r["peak_mib"] for r in runs)}


def table(cases: list[dict], repeat: int = 1) -> str:
    sizes, mus = _sizes_and_mus(cases)
    spaces = " ".join(dict.fromkeys(c["nullspace"] for c in cases))
    lines = ["# Krylov iterations against the contact stiffness (3-D Example 1, iterative, one process)", "",
             f"Command: `python -m studies.krylov_contact --sizes {sizes} --mu {mus} --nullspace {spaces} --repeat {repeat} "
             "--output benchmarks/results`. Level 0 and 10 steps of k = 0.02 (one cycle of Fischer's guess). "
             "The scene's mu is 1e-10; the plain "
             "elasticity solve (no contact) takes 17-19 iterations (scaling.md). Near-nullspace `rigid`: the six rigid "
             "motions; `contact`: the same without their normal component on Gamma_C (the default). The two of a "
             f"case ran one after the other, alternating, {repeat} time(s) each, on a shared 2-core machine; the step "
             "time is the mean displacement solve of the 10 steps (the median over the repeats), its ratio taken within the "
             "pair. Absolute times are not comparable between rows.", "",
             "| n | dofs | mu | near-nullspace | Krylov its / solve, level 0 | steps | step time / rigid's "
             "| contact force at T |", "|---|---|---|---|---|---|---|---|"]
    rigid = {(c["n"], c["mu"]): c["step_s"] for c in cases if c["nullspace"] == "rigid" and "failed" not in c}
    for c in sorted(cases, key=lambda c: (c["n"], c["mu"], NULLSPACES.index(c["nullspace"]))):
        if "failed" in c:
            lines.append(_failed_row(c, c["nullspace"], 3))
            continue
        ref = rigid.get((c["n"], c["mu"]))
        ratio = f"{c['step_s'] / ref:.2f}" if ref else "-"
        lines.append(f"| {c['n']} | {c['dofs']:,} | {c['mu']:g} | {c['nullspace']} | {c['level0']:.1f} | "
                     f"{c['steps']:.1f} | {ratio} | {c['contact_force']:.6g} |")
    return "\n".join(lines) + "\n"


def amg_table(cases: list[dict]) -> str:
    """The --amg comparison: iterations, step time and peak memory of each AMG against the solver's, per case."""
    sizes, mus = _sizes_and_mus(cases)
    amgs = " ".join(dict.fromkeys(c["amg"] for c in cases))
    lines = ["# Krylov iterations against the contact stiffness, by AMG (3-D Example 1, iterative, one process)", "",
             f"Command: `python -m studies.krylov_contact --sizes {sizes} --mu {mus} --amg {amgs} --output "
             "benchmarks/results`. Level 0 and 10 steps of k = 0.02, the contact near-nullspace. `gamg`: the solver's "
             "AMG, GAMG's smoothed aggregation set up anew when J changes; `ml`: Trilinos ML (smoothed aggregation, "
             "MIS), the solver's AMG before; `gamg-reuse`: GAMG keeping the interpolation of its first set-up "
             "(PETSc's default: K's, before the contact term). The runs of a case ran one after the other on a shared "
             "2-core machine; step time (the mean displacement solve of the steps) and peak memory (the process's) "
             "are read as ratios to `gamg`'s run of the same case.", "",
             "| n | dofs | mu | AMG | Krylov its / solve, level 0 | steps | step time / gamg's | peak MiB | "
             "peak / gamg's | contact force at T |", "|---|---|---|---|---|---|---|---|---|---|"]
    ref = {(c["n"], c["mu"]): c for c in cases if c["amg"] == "gamg" and "failed" not in c}
    for c in sorted(cases, key=lambda c: (c["n"], c["mu"], list(AMGS).index(c["amg"]))):
        if "failed" in c:
            lines.append(_failed_row(c, c["amg"], 5))
            continue
        r = ref.get((c["n"], c["mu"]))
        step = f"{c['step_s'] / r['step_s']:.2f}" if r else "-"
        peak = f"{c['peak_mib'] / r['peak_mib']:.2f}" if r else "-"
        lines.append(f"| {c['n']} | {c['dofs']:,} | {c['mu']:g} | {c['amg']} | {c['level0']:.1f} | {c['steps']:.1f} | "
                     f"{step} | {c['peak_mib']:,.0f} | {peak} | {c['contact_force']:.6g} |")
    return "\n".join(lines) + "\n"


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(prog="python -m studies.krylov_contact", description=__doc__.splitlines()[0])
    p.add_argument("--sizes", type=int, nargs="+", default=[14, 22])
    p.add_argument("--mu", type=float, nargs="+", default=[1e-10, 1e-6, 1e-3])
    p.add_argument("--nullspace", nargs="+", choices=NULLSPACES, default=list(NULLSPACES))
    p.add_argument("--amg", nargs="+", choices=list(AMGS), default=None,
                   help="compare these AMGs (contact near-nullspace) instead of the near-nullspaces")
    p.add_argument("--repeat", type=int, default=1, help="runs of each case, alternating (step time: their median)")
    p.add_argument("--output", default=None)
    a = p.parse_args(argv)
    bad = [(f"--sizes {n}", "must be >= 1") for n in a.sizes if n < 1] + [(f"--mu {m:g}", "must be > 0") for m in a.mu if m <= 0]
    bad += [(f"--repeat {a.repeat}", "must be >= 1")] if a.repeat < 1 else []
    if bad:
        print(f"error: {bad[0][0]}: {bad[0][1]}", file=sys.stderr)
        return 2
    if a.amg:
        return _compare_amgs(a)
    cases = []
    for n in a.sizes:
        for mu in a.mu:
            runs: dict[str, list[dict]] = {space: [] for space in a.nullspace}
            for _ in range(a.repeat):  # A B A B: the step times of a pair side by side
                for space in a.nullspace:
                    runs[space].append(run_case_apart(n, mu, space))
                    print(json.dumps(runs[space][-1]), flush=True)
            cases += [_merge(rs) for rs in runs.values()]
    text = table(cases, a.repeat)
    print(text)
    if a.output:
        Path(a.output, "krylov_contact.md").write_text(text)
    return 0


def _compare_amgs(a: argparse.Namespace) -> int:
    cases = []
    for n in a.sizes:
        for mu in a.mu:
            runs: dict[str, list[dict]] = {amg: [] for amg in a.amg}
            for _ in range(a.repeat):
                for amg in a.amg:
                    runs[amg].append(run_case_apart(n, mu, "contact", amg))
                    print(json.dumps(runs[amg][-1]), flush=True)
            cases += [_merge(rs) for rs in runs.values()]
    text = amg_table(cases)
    print(text)
    if a.output:
        Path(a.output, "krylov_contact_amg.md").write_text(text)
    return 0


if __name__ == "__main__":
    if len(sys.argv) == 6 and sys.argv[1] == "case":
        print(json.dumps(run_case(int(sys.argv[2]), float(sys.argv[3]), sys.argv[4], sys.argv[5])))
        raise SystemExit(0)
    raise SystemExit(main())
