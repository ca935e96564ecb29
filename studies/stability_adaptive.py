"""The stability map's adaptive columns (``study stability --methods adaptive``; docs/model.md §3.9).

For each cell (scene, mu, n, k) of the map: the uniform run with the step k (plain Newton, the map's default method)
and an adaptive run that starts at k and aims at the uniform run's time error (``time.tolerance`` = that error),
both measured by their time error: max over t = 0.1, 0.2, ..., 1 of ||eps(u - u_ref)|| + ||zeta - zeta_ref|| against
a uniform run on the same mesh with a step ``k_ref`` (at least 4 times finer than the finest k; the map's own error
column is against a finer mesh, where the mesh's error hides the step's). The adaptive run's steps (accepted and
rejected trials) are set against the uniform steps that reach its error, interpolated log-log along the cell's
column of k (as scripts/adaptive_work_precision.py does; beyond the column's errors along the line of its two nearest
runs, the observed order, and marked extrapolated). A cell fails (``adaptive_failure``) where the adaptive
run stops, where its error exceeds its tolerance, or where it needs more steps than the uniform run for the same
error: steps ratio > 1, or more trials than that cell's uniform run without a smaller error.
"""

from __future__ import annotations

import math
import time
from pathlib import Path

import numpy as np

CHECK = [i / 10 for i in range(1, 11)]  # every run has a level there (the adaptive one lands on them)
ADAPTIVE_COLUMNS = ["tolerance", "trials", "rejected", "time_error", "uniform_steps", "uniform_time_error",
                    "steps_ratio", "extrapolated", "reference_k", "reference_error", "judged", "adaptive_failure"]
RESOLVED = 2.0  # an adaptive error below this many times the reference's own error is not judged


def _run(cfg_path: Path, sets: list[str]) -> dict:
    """One run to T in this process: the fields at CHECK, levels, rejected trials, a failure or None, seconds."""
    from mpi4py import MPI

    from solver.config import load
    from solver.errors import SolveFailure
    from solver.run.model import build_model
    from solver.run.stepper import levels

    cfg = load(cfg_path, [*sets, "output.xdmf=false"])
    t0 = time.perf_counter()
    model = build_model(cfg, MPI.COMM_SELF)
    at, n, rejected, failure = {}, -1, 0, None
    try:
        for row in levels(model):
            n += 1
            rejected += int(row.get("rejected", 0))
            near = [c for c in CHECK if abs(row["t"] - c) <= 1e-9]
            if near:
                z = model.damage.zeta.x.array.copy() if model.damage is not None else None
                at[near[0]] = (model.u.x.array.copy(), z)
    except SolveFailure as exc:
        failure = exc
    return {"model": model, "at": at, "levels": n, "rejected": rejected, "failure": failure,
            "seconds": time.perf_counter() - t0}


class _Norm:
    """The time error of a run against the reference on the same mesh (max over CHECK of the paper's norm)."""

    def __init__(self, ref: dict) -> None:
        import dolfinx.fem.petsc  # noqa: F401
        import ufl
        from dolfinx import fem

        self.ref, model = ref, ref["model"]
        self.du = fem.Function(model.u.function_space)
        e = ufl.sym(ufl.grad(self.du))
        self.fu = fem.form(ufl.inner(e, e) * ufl.dx)
        self.dz = fem.Function(model.damage.V) if model.damage is not None else None
        self.fz = fem.form(self.dz * self.dz * ufl.dx) if self.dz is not None else None

    def __call__(self, run: dict) -> float:
        from dolfinx import fem

        if run["failure"] is not None or any(c not in run["at"] for c in CHECK):
            return math.nan
        worst = 0.0
        for c in CHECK:
            (u, z), (u_ref, z_ref) = run["at"][c], self.ref["at"][c]
            self.du.x.array[:] = u - u_ref
            out = math.sqrt(max(fem.assemble_scalar(self.fu), 0.0))
            if self.dz is not None:
                self.dz.x.array[:] = z - z_ref
                out += math.sqrt(max(fem.assemble_scalar(self.fz), 0.0))
            worst = max(worst, out)
        return worst


def uniform_steps_at(err: float, uniform: list[tuple[float, float]]) -> tuple[float, bool]:
    """The uniform steps that reach the time error ``err``, log-log between the two uniform runs around it, or
    beyond the range along the line of the two nearest (the observed order), and whether it was extrapolated;
    ``uniform``: (error, steps) pairs (NaN with fewer than two)."""
    pts = sorted((e, s) for e, s in uniform if e > 0 and math.isfinite(e))
    if len(pts) < 2 or not err > 0:
        return math.nan, False
    inside = pts[0][0] <= err <= pts[-1][0]
    pair = next(((a, b) for a, b in zip(pts, pts[1:]) if a[0] <= err <= b[0]), None)
    if pair is None:
        pair = (pts[0], pts[1]) if err < pts[0][0] else (pts[-2], pts[-1])
    (e0, s0), (e1, s1) = pair
    if e1 <= e0:
        return math.nan, False
    w = (math.log(err) - math.log(e0)) / (math.log(e1) - math.log(e0))
    return math.exp(math.log(s0) + w * (math.log(s1) - math.log(s0))), not inside


def reference_error(k_ref: float, column: list[tuple[float, float]]) -> float:
    """The reference's own time error, from the finest uniform run of the column ((k, error) pairs): at order 1 the
    error measured against the reference is C (k - k_ref) and the reference's own C k_ref."""
    pts = sorted((k, e) for k, e in column if k > k_ref and isinstance(e, (int, float)) and math.isfinite(e))
    if not pts:
        return math.nan
    k, e = pts[0]
    return e * k_ref / (k - k_ref)


def judge(rows: list[dict], k_ref: float | None = None) -> None:
    """Fill each adaptive row's reference_error (from its column and reference_k, or ``k_ref`` where the row has
    none), whether it is judged (its error at least RESOLVED times the reference's own) and its failure."""
    sub = [r for r in rows if r["method"] == "adaptive"]
    for r in sub:
        if not isinstance(r.get("reference_k"), (int, float)):
            r["reference_k"] = k_ref
        column = [(c["k"], c["uniform_time_error"]) for c in sub
                  if (c["scene"], c["mu"], c["n"]) == (r["scene"], r["mu"], r["n"])]
        r["reference_error"] = reference_error(r["reference_k"], column)
        err = r.get("time_error")
        r["judged"] = isinstance(err, (int, float)) and err >= RESOLVED * r["reference_error"]
        r["adaptive_failure"] = failure_of(r)


def failure_of(row: dict) -> str:
    """Why an adaptive cell fails ('' when it does not): stopped, unreliable, more steps for the same error; a cell
    whose error is within RESOLVED times the reference's own (``judged`` false) is not judged on its steps or error."""
    if row["status"] != "converged":
        return "stopped" if row["status"] != "no_uniform_run" else ""
    if not row.get("judged", True):
        return ""
    out = []
    if not row["time_error"] <= row["tolerance"]:
        out.append("error above the tolerance")
    ratio = row["steps_ratio"]
    if (math.isfinite(ratio) and ratio > 1.0) or (
            row["trials"] > row["uniform_steps"] and not row["time_error"] < row["uniform_time_error"]):
        out.append("more steps than uniform" + (" (extrapolated)" if row["extrapolated"] else ""))
    return "; ".join(out)


def adaptive_group(args: tuple) -> list[dict]:
    """The adaptive cells of one (scene, mu, n): the same-mesh reference, the uniform column and the adaptive runs."""
    cfg_path, scene, mu, n, ks, k_ref, max_it = args
    base = [f"boundary.bottom.mu={mu!r}", f"mesh.nx={n}", f"mesh.ny={n}", "solver.method='newton'",
            f"solver.max_it={max_it}"]
    ref = _run(cfg_path, [*base, f"time.k={k_ref!r}"])
    if ref["failure"] is not None:
        raise RuntimeError(f"the reference of {scene} mu={mu:g} n={n} (k = {k_ref:g}) stopped: {ref['failure']}")
    norm = _Norm(ref)
    uniform = {}
    for k in ks:
        run = _run(cfg_path, [*base, f"time.k={k!r}"])
        uniform[k] = (norm(run), run["levels"] if run["failure"] is None else math.nan)
    pairs = [v for v in uniform.values() if math.isfinite(v[1])]
    marks = "output.times=[" + ", ".join(f"{c:g}" for c in CHECK[:-1]) + "]"
    rows = []
    for k in ks:
        e_uniform, steps = uniform[k]
        tol = e_uniform if math.isfinite(e_uniform) and e_uniform > 0 else math.nan
        row = {"scene": scene, "method": "adaptive", "mu": mu, "n": n, "k": k, "tolerance": tol,
               "uniform_steps": steps, "uniform_time_error": e_uniform, "reference_k": k_ref}
        if not math.isfinite(tol):  # the uniform run stopped: no error to aim at
            row.update({"status": "no_uniform_run", "reason": "the uniform run of this cell stopped",
                        "adaptive_failure": "", "trials": math.nan, "rejected": math.nan, "time_error": math.nan,
                        "steps_ratio": math.nan, "extrapolated": False, "levels": 0, "seconds": 0.0})
            rows.append(row)
            continue
        run = _run(cfg_path, [*base, "time.adaptive=true", f"time.k={k!r}", f"time.tolerance={tol!r}", marks])
        err = norm(run)
        trials = run["levels"] + run["rejected"]
        row.update({"status": "converged" if run["failure"] is None else run["failure"].kind,
                    "reason": "" if run["failure"] is None else str(run["failure"]),
                    "failed_step": "" if run["failure"] is None else run["failure"].step,
                    "levels": run["levels"], "trials": trials, "rejected": run["rejected"], "time_error": err,
                    "seconds": run["seconds"]})
        at, extrapolated = uniform_steps_at(err, pairs) if math.isfinite(err) else (math.nan, False)
        row["steps_ratio"], row["extrapolated"] = trials / at, extrapolated
        rows.append(row)
    judge(rows)
    return rows


def adaptive_map(rows: list[dict], out: Path) -> Path | None:
    """stability_adaptive.png: per scene and n, the steps ratio over (k, mu); failed cells marked."""
    from solver.post.charts import pyplot

    plt = pyplot("the adaptive stability map")
    sub = [r for r in rows if r["method"] == "adaptive"]
    if plt is None or not sub:
        return None
    from matplotlib.colors import LogNorm

    panels = list(dict.fromkeys((r["scene"], r["n"]) for r in sub))
    fig, axes = plt.subplots(1, len(panels), figsize=(5.2 * len(panels) + 1, 4.4), squeeze=False)
    im = None
    for j, (scene, n) in enumerate(panels):
        ax = axes[0][j]
        cells = [r for r in sub if r["scene"] == scene and r["n"] == n]
        mus = sorted({r["mu"] for r in cells}, reverse=True)
        ks = sorted({r["k"] for r in cells}, reverse=True)
        grid = np.full((len(ks), len(mus)), np.nan)
        for r in cells:
            a, b = ks.index(r["k"]), mus.index(r["mu"])
            ratio = r["steps_ratio"]
            if isinstance(ratio, (int, float)) and math.isfinite(ratio) and r["status"] == "converged":
                grid[a, b] = ratio
                text = ("~" if r.get("extrapolated") else "") + f"{ratio:.2f}"
            else:
                text = "X" if r["status"] != "no_uniform_run" else "-"
            bad = bool(r.get("adaptive_failure"))
            unjudged = r["status"] != "converged" or not r.get("judged", True)
            if unjudged:
                grid[a, b] = np.nan
                text += "\n?" if r["status"] == "converged" else ""
            ax.text(b, a, text + ("\nFAIL" if bad else ""), ha="center", va="center", fontsize=6,
                    color="darkred" if bad else "white" if unjudged else "black",
                    fontweight="bold" if bad else "normal")
        ax.set_facecolor("#444444")
        im = ax.imshow(grid, cmap="coolwarm", norm=LogNorm(vmin=0.25, vmax=4.0), aspect="auto")
        ax.set_xticks(range(len(mus)), [f"{math.log10(m):.0f}" for m in mus], fontsize=7)
        ax.set_yticks(range(len(ks)), [f"{k:g}" for k in ks], fontsize=7)
        ax.set_xlabel("log10 mu", fontsize=8)
        ax.set_ylabel("first step k (uniform run: k)", fontsize=8)
        ax.set_title(f"{scene}, n = {n}", fontsize=9)
    fig.subplots_adjust(top=0.82)
    bar = fig.colorbar(im, ax=axes, label="adaptive trials / uniform steps at the same time error")
    bar.set_ticks([0.25, 0.5, 1.0, 2.0, 4.0], labels=["1/4", "1/2", "1", "2", "4"])
    bar.minorticks_off()
    fig.suptitle("Adaptive steps starting at k, tolerance = the uniform run's time error: steps ratio (blue < 1 < red)\n"
                 "~: extrapolated beyond the uniform runs' errors; FAIL: more steps for the same error, or error > "
                 "tolerance; X: stopped; grey with ?: error within 2x the reference's own, not judged", fontsize=8)
    path = out / "stability_adaptive.png"
    fig.savefig(path, dpi=110)
    plt.close(fig)
    return path


def verdict(r: dict) -> str:
    """A cell's failure column: its failure, 'not judged' (within RESOLVED times the reference's error) or 'none'."""
    if r.get("adaptive_failure"):
        return r["adaptive_failure"]
    if r["status"] != "converged":
        return r["status"]
    return "none" if r.get("judged", True) else f"not judged (reference's own error ~{r['reference_error']:.2g})"


def adaptive_table(rows: list[dict], out: Path, command: str) -> Path | None:
    """stability_adaptive.md: the adaptive cells, failures first counted."""
    sub = [r for r in rows if r["method"] == "adaptive"]
    if not sub:
        return None

    def num(v, fmt: str) -> str:
        return format(v, fmt) if isinstance(v, (int, float)) and math.isfinite(v) else "-"

    failed = [r for r in sub if r.get("adaptive_failure")]
    lines = ["# The stability map's adaptive columns", "", f"`{command}`", "",
             "Each cell: the uniform run with step k and an adaptive run starting at k with time.tolerance = the "
             "uniform run's time error (max over t = 0.1, ..., 1 of the paper's norm against a uniform run with "
             "a finer step on the same mesh). Steps ratio: the adaptive run's trials (accepted + rejected) over the "
             "uniform steps that reach its error (log-log along the column of k; '~': beyond the column's errors, "
             "along the line of its two nearest runs). Failure: stopped, error above the tolerance, or more steps "
             "than uniform for the same error. Not judged: an adaptive error below 2 x the reference's own error (from the "
             "column's finest uniform run at order 1: e_min k_ref / (k_min - k_ref)), where the reference cannot tell "
             "the two runs apart.",
             "", f"{len(sub)} cells, {sum(r['status'] == 'converged' for r in sub)} reached T, {len(failed)} failures, "
             f"{sum(not r.get('judged', True) for r in sub)} not judged.",
             "", "| scene | n | mu | k | tolerance | adaptive error | trials (rejected) | uniform steps | steps ratio | "
             "failure |", "|---|---|---|---|---|---|---|---|---|---|"]
    for r in sorted(sub, key=lambda r: (r["scene"], r["n"], -r["mu"], -r["k"])):
        lines.append(f"| {r['scene']} | {r['n']} | {r['mu']:g} | {r['k']:g} | {num(r['tolerance'], '.3g')} | "
                     f"{num(r['time_error'], '.3g')} | {num(r['trials'], '.0f')} ({num(r['rejected'], '.0f')}) | "
                     f"{num(r['uniform_steps'], '.0f')} | {'~' if r.get('extrapolated') else ''}{num(r['steps_ratio'], '.2f')} | "
                     f"{verdict(r)} |")
    path = out / "stability_adaptive.md"
    path.write_text("\n".join(lines) + "\n")
    return path


def main(argv: list[str] | None = None) -> int:
    """Judge the adaptive rows of a stability.csv again and redraw stability_adaptive.{md,png} (no runs)."""
    import argparse

    from studies import REPO
    from studies.study import _read_rows, _write_csv

    p = argparse.ArgumentParser(prog="python -m studies.stability_adaptive", description=main.__doc__)
    p.add_argument("--output", default=str(REPO / "benchmarks" / "results"))
    p.add_argument("--reference-k", type=float, default=None, help="for rows written without their reference_k")
    p.add_argument("--command", default="", help="the study command the rows came from (the table's header)")
    args = p.parse_args(argv)
    out = Path(args.output)
    rows = _read_rows(out / "stability.csv")
    judge(rows, args.reference_k)
    _write_csv(rows, out / "stability.csv")
    for path in (adaptive_map(rows, out), adaptive_table(rows, out, args.command)):
        print(path)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
