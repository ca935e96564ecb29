"""Where in time the time error is made: how much of it a better step sequence could save (docs/model.md §3.9).

For each scene (8 x 8, order 1): the error of 80 uniform steps against a fine uniform reference (``--ref`` steps),
and of 80 uniform steps with the steps of one window of [0, T] halved, for each of ``--windows`` windows; the error
is :mod:`adaptive_work_precision`'s (max over t = 0.1, ..., 1 of the paper's norm). A window's reduction d_i
measures the error the steps there make: a first-order scheme's local error c(t) k^2 summed over a run of N steps
is smallest, N·error = (∫ c^(1/2) dt)^2, with k ~ c^(-1/2) (an equal error per step); uniform steps give T ∫ c dt.
With c ~ d_i the best step sequence takes (mean d_i^(1/2))^2 / mean d_i of the uniform run's steps for the same
error: below 1/2 only where the error is made in a small part of [0, T]. That figure assumes that the windows'
savings add up; in the max over t they do not (an error made after the time of the max is hidden only while it
stays below the max), so ``--sequences`` also measures step sequences directly: N1 steps per unit of time before
a split time s and N2 after it (one level added on every awp.CHECK time), each against the uniform runs with 10·2^j
steps (interpolated log-log, as awp), giving the steps ratio that sequence achieves.

    python scripts/adaptive_error_density.py [--scenes example1 hard load_cycle] [--ref 2560] [--windows 10]
        [--sequences N1,s,N2 ...]

writes benchmarks/results/adaptive_error_density.md.
"""

from __future__ import annotations

import argparse
import math
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


def sequences(scene: str, ref: dict, ref_steps: int, specs: list[str]) -> list[dict]:
    """Two-phase step sequences N1,s,N2 and the steps ratio each achieves against uniform runs."""
    uniform = []
    for n in awp.UNIFORM:
        if 4 * n <= ref_steps:
            run = run_times(scene, [i / n for i in range(n + 1)])
            uniform.append({"levels": n, "error": awp.error(ref, run)})
    out = []
    for spec in specs:
        n1, split, n2 = spec.split(",")
        n1, split, n2 = int(n1), float(split), int(n2)
        times = {round(i / n1, 12) for i in range(int(round(split * n1)) + 1)}
        times |= {round(split + i / n2, 12) for i in range(int(round((1 - split) * n2)) + 1)}
        times |= {round(c, 12) for c in awp.CHECK}
        times = sorted(t for t in times if t <= 1.0 + 1e-12)
        e = awp.error(ref, run_times(scene, times))
        steps = len(times) - 1
        out.append({"spec": spec, "steps": steps, "error": e, "ratio": steps / awp.uniform_at(e, uniform, "levels")})
    return out


def gram_forms(model):
    """The paper's norm's two inner products as scipy matrices: (eps(u), eps(v)) on u's space, (z, w) on zeta's."""
    import dolfinx.fem.petsc  # noqa: F401
    import scipy.sparse as sp
    import ufl
    from dolfinx import fem

    def csr(form):
        A = dolfinx.fem.petsc.assemble_matrix(fem.form(form))
        A.assemble()
        indptr, indices, data = A.getValuesCSR()
        return sp.csr_matrix((data, indices, indptr), shape=A.getSize())

    V = model.u.function_space
    u, v = ufl.TrialFunction(V), ufl.TestFunction(V)
    Ku = csr(ufl.inner(ufl.sym(ufl.grad(u)), ufl.sym(ufl.grad(v))) * ufl.dx)
    Kz = None
    if model.damage is not None:
        z, w = ufl.TrialFunction(model.damage.V), ufl.TestFunction(model.damage.V)
        Kz = csr(z * w * ufl.dx)
    return Ku, Kz


def best_sequence(scene: str, ref_steps: int) -> dict:
    """The best step sequence in the linear model of the error (first order): with the steps of window i (one
    tenth of [0, T]) at s_i times BASE's, the error field at the tenth t_j is sum_i s_i D_ij, D_ij = 2 (the BASE
    run's field - the field with window i's steps halved). The paper's norm at t_j is then
    ||sum_i s_i Du_ij||_eps + ||sum_i s_i Dz_ij||, a max over j of norms of linear combinations (signed: errors of
    opposite signs cancel, an error hidden under the max is free). The steps ratio at equal error is scale-free,
    (mean 1/s_i) max_j e_j(s) / max_j e_j(1), minimised over s (Nelder-Mead on log s, restarts); the minimiser's
    sequence is then run and measured against uniform runs, which checks the model."""
    import numpy as np
    from scipy.optimize import minimize

    ref = awp.one_run(scene, [f"time.k={1.0 / ref_steps}"])
    Ku, Kz = gram_forms(ref["model"])
    W, per = 10, BASE // 10
    base = run_times(scene, [i / BASE for i in range(BASE + 1)])["at"]
    D = []  # D[i][j] = (du, dz)
    for i in range(W):
        a, b = i / W, (i + 1) / W
        times = sorted({round(t, 12) for t in [k / BASE for k in range(BASE + 1)]
                        + [a + (b - a) * k / (2 * per) for k in range(2 * per + 1)]})
        half = run_times(scene, times)["at"]
        D.append([(2 * (base[c][0] - half[c][0]), 2 * (base[c][1] - half[c][1]) if Kz is not None else None)
                  for c in awp.CHECK])
    # Gram matrices per check time
    Gu = np.array([[[D[i][j][0] @ (Ku @ D[m][j][0]) for m in range(W)] for i in range(W)] for j in range(W)])
    Gz = np.array([[[D[i][j][1] @ (Kz @ D[m][j][1]) for m in range(W)] for i in range(W)] for j in range(W)]) \
        if Kz is not None else np.zeros_like(Gu)

    def errs(s):
        return np.array([math.sqrt(max(s @ Gu[j] @ s, 0.0)) + math.sqrt(max(s @ Gz[j] @ s, 0.0)) for j in range(W)])

    one = np.ones(W)
    e1 = errs(one).max()
    # the model against the measured error of the BASE run (the sum of the windows' errors is the run's error)
    measured = awp.error(ref, {"at": base})

    def ratio(x):
        s = np.exp(x)
        return float(np.mean(1.0 / s) * errs(s).max() / e1)

    best = None
    rng = np.random.default_rng(0)
    for start in [np.zeros(W)] + [rng.normal(0, 1, W) for _ in range(5)]:
        r = minimize(ratio, start, method="Nelder-Mead", options={"maxiter": 20000, "maxfev": 20000,
                                                                  "xatol": 1e-4, "fatol": 1e-6})
        if best is None or r.fun < best.fun:
            best = r
    s = np.exp(best.x)
    # run it: window i with per/s_i steps, scaled to about 2 BASE steps in all
    scale = 2.0 * W * per / float(np.sum(per / s))
    counts = [max(1, round(scale * per / si)) for si in s]
    times = sorted({round((i + m / n) / W, 12) for i, n in enumerate(counts) for m in range(n)} | {1.0})
    run = run_times(scene, times)
    e = awp.error(ref, run)
    uniform = []
    for n in awp.UNIFORM:
        if 4 * n <= ref_steps:
            uniform.append({"levels": n, "error": awp.error(ref, run_times(scene, [k / n for k in range(n + 1)]))})
    steps = len(times) - 1
    return {"best": {"model_error_uniform": float(e1), "measured_error_uniform": float(measured),
                     "model_ratio": float(best.fun), "s": [float(x) for x in s], "counts": counts, "steps": steps,
                     "error": e, "ratio": steps / awp.uniform_at(e, uniform, "levels")}}


def density(scene: str, ref_steps: int, windows: int, specs: list[str] | None = None) -> dict:
    ref = awp.one_run(scene, [f"time.k={1.0 / ref_steps}"])
    if specs:
        return {"sequences": sequences(scene, ref, ref_steps, specs)}
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
    seq = f" --sequences {' '.join(args.sequences)}" if args.sequences else " --best" if args.best else ""
    lines = ["# Where the time error is made", "",
             f"`python scripts/adaptive_error_density.py --scenes {' '.join(args.scenes)} --ref {args.ref} "
             f"--windows {args.windows}{seq}` (8 x 8, order 1; error: max over t = 0.1, ..., 1 of the paper's norm "
             f"against {args.ref} uniform steps). " + (
                 "The best step sequence in the linear model of the error: the steps of window i (one tenth) at s_i "
                 f"times {BASE} uniform steps', the error field at the tenth t_j = sum_i s_i D_ij (D_ij: twice the "
                 f"change of the field at t_j when window i's steps are halved), the paper's norm at t_j of that, "
                 "its max over j; the steps ratio at equal error (mean 1/s_i) max_j e_j(s) / max_j e_j(1) minimised "
                 "over s (Nelder-Mead on log s, 6 starts), then that sequence run and measured against uniform runs "
                 "10 2^j (log-log)." if args.best else
                 "Each row: N1 steps per unit of time before s, N2 after (and a level on every tenth); steps ratio: "
                 "its steps over the uniform run's that reaches its error (uniform runs 10 2^j steps, log-log)."
                 if args.sequences else
                 f"Each row: {BASE} uniform steps with the steps of one window "
                 "halved, and the error that saves. Best ratio: (mean d^(1/2))^2 / mean d, the steps the best step "
                 "sequence would take over the uniform run's for the same error (first order, c(t) ~ the window's "
                 "saving d) if the windows' savings added up; in the max over t they do not (see "
                 "adaptive_error_density_sequences.md)."), ""]
    for scene, r in data.items():
        if "best" in r:
            b = r["best"]
            lines += [f"## {scene}: the best step sequence", "",
                      f"The linear model's error of {BASE} uniform steps {b['model_error_uniform']:.3g} "
                      f"(measured {b['measured_error_uniform']:.3g}). **Best steps ratio in the model "
                      f"{b['model_ratio']:.2f}**; that sequence run ({b['steps']} steps, per tenth "
                      f"{', '.join(str(c) for c in b['counts'])}): error {b['error']:.3g}, **measured steps ratio "
                      f"{b['ratio']:.2f}**.", ""]
            continue
        if "sequences" in r:
            lines += [f"## {scene}: step sequences", "", "| N1 per unit before s, s, N2 after | steps | error | steps "
                      "ratio (uniform at that error) |", "|---|---|---|---|"]
            lines += [f"| {q['spec']} | {q['steps']} | {q['error']:.3g} | {q['ratio']:.2f} |" for q in r["sequences"]]
            lines.append("")
            continue
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
    p.add_argument("--sequences", nargs="+", default=None, help="N1,s,N2: two-phase step sequences to measure")
    p.add_argument("--best", action="store_true", help="the best step sequence in the linear error model")
    args = p.parse_args()
    data = {}
    name = "adaptive_error_density_" + ("best.md" if args.best else "sequences.md" if args.sequences else "")
    name = name.rstrip("_") + ("" if name.endswith(".md") else ".md")
    for scene in args.scenes:
        data[scene] = best_sequence(scene, args.ref) if args.best else \
            density(scene, args.ref, args.windows, args.sequences)
        (ROOT / "benchmarks/results" / name).write_text(markdown(data, args))
        print(markdown({scene: data[scene]}, args), flush=True)


if __name__ == "__main__":
    main()
