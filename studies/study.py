"""Where methods fail, and what accuracy a second buys (``python -m studies study ...``).

``study stability``: every displacement method (and the semi-implicit damage variant) over
a sweep of the compliance mu, the step k and two meshes, on Example 1 and on a harder
scene (configs/hard.toml: damage reaches zeta*, the contact zone moves). Each point gets
a status (converged, diverged, stagnated, too many iterations, damage solve failed,
non-finite) with the reason, iterations and linear solves per step, the maximum
penetration, whether zeta left [zeta*, 1] before clipping, and the error against a fine
reference (same scene and mu; Newton, n_ref, k_ref). Writes stability.csv and one heat
map per method.

``study table1-variants``: which measurement of the error reproduces the paper's Table 1
(studies/table1_variants.py; writes table1_variants.md, .csv, .json).

``study work-precision``: error against the reference versus wall time over (n, k) for
each method and variant on Example 1, with the Pareto front. Writes work_precision.csv
and work_precision.png.

Both run their (scene, mu) groups in worker processes (``--jobs``).
"""

from __future__ import annotations

import argparse
import csv
import json
import math
import sys
import time
from concurrent.futures import ProcessPoolExecutor
from multiprocessing import get_context
from pathlib import Path

import numpy as np

from solver.errors import SolveFailure
from solver.post.charts import pyplot
from studies import REPO as ROOT  # noqa: E402
from studies.stability_adaptive import ADAPTIVE_COLUMNS, adaptive_group, adaptive_map, adaptive_table
from studies.table1_variants import VARIANTS as T1_VARIANTS

SCENES = {"example1": ROOT / "configs" / "example1.toml", "hard": ROOT / "configs" / "hard.toml"}
MUS = [10.0 ** -e for e in range(0, 13)]
KS = [0.1, 0.05, 0.01, 0.005, 0.001, 0.0005]
NS = [8, 16]
# label -> scene overrides; the damage variant is swept at the paper's mu only
VARIANTS = {
    "newton": ["solver.method='newton'"],
    "newton_energy": ["solver.method='newton_energy'"],
    "newton_condensed": ["solver.method='newton_condensed'"],
    "penalty_duality": ["solver.method='penalty_duality'"],
    "fixed_point": ["solver.method='fixed_point'"],
    "newton+semi_implicit_damage": ["solver.method='newton'", "solver.damage_scheme='semi_implicit'"],
    "newton+trapezoid_memory": ["solver.method='newton'", "memory.rule='trapezoid'"],
    # steps chosen by the controller (time.adaptive), each cell's run aiming at its uniform run's time error
    "adaptive": ["solver.method='newton'", "time.adaptive=true"],
}
COLUMNS = ["scene", "method", "mu", "n", "k", "status", "reason", "failed_step", "iterations_per_step",
           "max_iterations", "linear_solves_per_step", "factorizations", "max_penetration", "zeta_left_range",
           "zeta_raw_min", "zeta_raw_max", "error", "error_u", "error_zeta", "error_T", "levels", "seconds",
           *ADAPTIVE_COLUMNS]


def _status(failure: SolveFailure | None) -> tuple[str, str]:
    """The study's status word and reason for a run's outcome (from the failure's type and fields)."""
    if failure is None:
        return "converged", ""
    return failure.kind, str(failure)


def _point(ref, scene: str, label: str, mu: float, n: int, k: float, max_it: int) -> dict:
    extra = [*VARIANTS[label], f"solver.max_it={max_it}"]
    row = {"scene": scene, "method": label, "mu": mu, "n": n, "k": k, "status": "converged", "reason": "",
           "failed_step": ""}
    rec, rows = ref.measure(extra, n, k)
    if rec["failure"] is not None:  # every failure is recorded with its reason
        row["status"], row["reason"] = _status(rec["failure"])
        row["failed_step"] = rec["failure"].step
    zstar = ref.model.cfg.damage.zeta_star
    its = [r["newton_iterations"] for r in rows[1:]] or [0]
    row.update({
        "iterations_per_step": float(np.mean(its)), "max_iterations": int(max(its)),
        "linear_solves_per_step": float(np.mean([r["linear_solves"] for r in rows[1:]] or [0])),
        "factorizations": int(sum(r["factorizations"] for r in rows)),
        "max_penetration": max((r["max_penetration"] for r in rows), default=float("nan")),
        "zeta_raw_min": min((r["zeta_raw_min"] for r in rows), default=float("nan")),
        "zeta_raw_max": max((r["zeta_raw_max"] for r in rows), default=float("nan")),
        "error": rec["error"] if rows else float("nan"), "error_u": rec["error_u"] if rows else float("nan"),
        "error_zeta": rec["error_zeta"] if rows else float("nan"), "levels": rec["levels"], "seconds": rec["seconds"],
        "error_T": rec["error_T"] if rows else float("nan"),
    })
    row["zeta_left_range"] = bool(rows) and (row["zeta_raw_min"] < zstar - 1e-12 or row["zeta_raw_max"] > 1 + 1e-12)
    return row


def _stability_group(args: tuple) -> list[dict]:
    scene, mu, labels, ns, ks, n_ref, k_ref, cache, max_it = args
    from studies.convergence import Reference

    ref = Reference(SCENES[scene], n_ref, k_ref, ks, Path(cache), [f"boundary.bottom.mu={mu!r}"])
    out = []
    for label in labels:
        for n in ns:
            for k in ks:
                out.append(_point(ref, scene, label, mu, n, k, max_it))
    return out


def _write_csv(rows: list[dict], path: Path) -> None:
    with open(path, "w", newline="") as fh:
        w = csv.DictWriter(fh, fieldnames=COLUMNS, extrasaction="ignore")
        w.writeheader()
        w.writerows(rows)


def heatmaps(rows: list[dict], out: Path, prefix: str = "stability") -> list[Path]:
    """One heat map per method of iterations per step over (k, mu), a panel per scene and n; failed cells marked
    by their status. Written as ``{prefix}_{method}.png``."""
    plt = pyplot("the stability maps")
    if plt is None:
        return []
    from matplotlib.colors import LogNorm

    made = []
    marks = {"diverged": "D", "stagnated": "S", "too_many_iterations": "M", "damage_failed": "F", "non_finite": "N",
             "failed": "X"}
    for label in dict.fromkeys(r["method"] for r in rows if r["method"] != "adaptive"):  # adaptive: its own map
        sub = [r for r in rows if r["method"] == label]
        scenes = list(dict.fromkeys(r["scene"] for r in sub))
        ns = sorted({r["n"] for r in sub})
        mus = sorted({r["mu"] for r in sub}, reverse=True)
        ks = sorted({r["k"] for r in sub}, reverse=True)
        fig, axes = plt.subplots(len(scenes), len(ns), figsize=(4.6 * len(ns) + 1, 3.2 * len(scenes) + 0.6),
                                 squeeze=False)
        vmax = max([r["iterations_per_step"] for r in sub if r["status"] == "converged"] or [2])
        im = None
        for i, scene in enumerate(scenes):
            for j, n in enumerate(ns):
                ax = axes[i][j]
                grid = np.full((len(ks), len(mus)), np.nan)
                for r in sub:
                    if r["scene"] != scene or r["n"] != n:
                        continue
                    a, b = ks.index(r["k"]), mus.index(r["mu"])
                    if r["status"] == "converged":
                        grid[a, b] = max(r["iterations_per_step"], 1.0)
                    else:
                        ax.text(b, a, marks.get(r["status"], "X"), ha="center", va="center", color="white",
                                fontsize=8, fontweight="bold")
                    if r["zeta_left_range"] and r["status"] == "converged":
                        ax.text(b, a, "*", ha="center", va="center", color="red", fontsize=11)
                ax.set_facecolor("#444444")
                im = ax.imshow(grid, cmap="viridis", norm=LogNorm(vmin=1, vmax=max(vmax, 2)), aspect="auto")
                ax.set_xticks(range(len(mus)), [f"{math.log10(m):.0f}" for m in mus], fontsize=7)
                ax.set_yticks(range(len(ks)), [f"{k:g}" for k in ks], fontsize=7)
                ax.set_xlabel("log10 mu", fontsize=8)
                ax.set_ylabel("k", fontsize=8)
                ax.set_title(f"{scene}, n = {n}", fontsize=9)
        fig.colorbar(im, ax=axes, label="iterations per step (converged)")
        fig.suptitle(f"{label}: grey = failed (D diverged, S stagnated, M too many iterations, F damage solve, "
                     f"N non-finite); red * = zeta left [zeta*, 1] before clipping", fontsize=8)
        path = out / f"{prefix}_{label}.png"
        fig.savefig(path, dpi=110)
        plt.close(fig)
        made.append(path)
    return made


def stability(args) -> int:
    out = Path(args.output)
    out.mkdir(parents=True, exist_ok=True)
    groups = []
    for scene in args.scenes:
        methods = [m for m in args.methods if "+" not in m and m != "adaptive"]
        for mu in args.mus if methods else []:
            groups.append((scene, mu, methods, args.ns, args.ks, args.ref_n, args.ref_k, args.cache, args.max_it))
        # the damage variant's stability depends on k and the damage, not on mu: swept at the paper's mu
        variants = [m for m in args.methods if "+" in m]
        if variants:
            groups.append((scene, 1e-10, variants, args.ns, args.ks, args.ref_n, args.ref_k, args.cache, args.max_it))
    rows = _run_groups(_stability_group, groups, args.jobs) if groups else []
    if "adaptive" in args.methods:  # per (scene, mu, n): a reference on that mesh, the uniform column, the cells
        k_ref = args.adaptive_ref_k or min(args.ks) / 4
        cells = [(SCENES[scene], scene, mu, n, args.ks, k_ref, args.max_it) for scene in args.scenes
                 for mu in args.mus for n in args.ns]
        rows += _run_groups(adaptive_group, cells, args.jobs)
    rows = _kept_rows(out / "stability.csv", rows)
    _write_csv(rows, out / "stability.csv")
    for path in heatmaps(rows, out):
        print(path)
    command = "python -m studies study stability " + " ".join(getattr(args, "argv", None) or sys.argv[3:])
    for path in (adaptive_map(rows, out), adaptive_table(rows, out, command.strip())):
        if path is not None:
            print(path)
    counts: dict[str, dict[str, int]] = {}
    for r in rows:
        counts.setdefault(r["method"], {}).setdefault(r["status"], 0)
        counts[r["method"]][r["status"]] += 1
    for label, c in counts.items():
        print(f"{label:32s} " + ", ".join(f"{k}: {v}" for k, v in sorted(c.items())))
    print(f"wrote {out / 'stability.csv'}")
    return 0


def _kept_rows(path: Path, rows: list[dict]) -> list[dict]:
    """The rows of ``path`` (an earlier run's CSV) that were not measured now, then the measured rows: a run of
    some methods (or cells) adds or replaces their points without running the others again."""
    if not path.exists():
        return rows

    def key(r: dict) -> tuple:
        return r["scene"], r["method"], float(r["mu"]), int(r["n"]), float(r["k"])

    measured = {key(r) for r in rows}
    return [r for r in _read_rows(path) if key(r) not in measured] + rows


def _wp_group(args: tuple) -> list[dict]:
    scene, labels, ns, ks, n_ref, k_ref, cache, mu = args
    from studies.convergence import Reference

    ref = Reference(SCENES[scene], n_ref, k_ref, ks, Path(cache), [f"boundary.bottom.mu={mu!r}"])
    return [_point(ref, scene, label, mu, n, k, 200) for label in labels for n in ns for k in ks]


def pareto(points: list[tuple[float, float]]) -> list[int]:
    """Indices of the points not beaten in both time and error (lower is better in both)."""
    order = sorted(range(len(points)), key=lambda i: (points[i][0], points[i][1]))
    front, best = [], math.inf
    for i in order:
        if points[i][1] < best:
            front.append(i)
            best = points[i][1]
    return front


def _read_rows(path: Path) -> list[dict]:
    """Rows of a CSV this command wrote, numbers as numbers."""
    def value(v: str):
        if v in ("True", "False"):
            return v == "True"
        for kind in (int, float):  # ints stay ints, so a CSV read and written again is unchanged
            try:
                return kind(v)
            except ValueError:
                pass
        return v

    with open(path, newline="") as fh:
        return [{k: value(v) for k, v in r.items()} for r in csv.DictReader(fh)]


DISC_COLUMNS = ["series", "n", "k", "u_degree", "zeta_degree", "order", "dofs_u", "status", "error", "error_u",
                "error_zeta", "t_max", "error_T", "levels_compared", "loop_seconds", "pareto_series", "pareto_all"]


def _methods_part(args, out: Path) -> list[dict]:
    from studies.convergence import Reference

    Reference(SCENES["example1"], args.ref_n, args.ref_k, args.ks, Path(args.cache), ["boundary.bottom.mu=1e-10"])
    groups = [("example1", [m], args.ns, args.ks, args.ref_n, args.ref_k, args.cache, 1e-10) for m in args.methods]
    rows = _run_groups(_wp_group, groups, args.jobs)
    rows = _kept_rows(out / "work_precision.csv", rows)
    ok = [r for r in rows if r["status"] == "converged"]
    for key in ("error", "error_T"):
        front = set(pareto([(r["seconds"], r[key]) for r in ok]))
        for i, r in enumerate(ok):
            r[f"pareto_{key}"] = i in front
    cols = [*COLUMNS, "pareto_error", "pareto_error_T"]
    with open(out / "work_precision.csv", "w", newline="") as fh:
        w = csv.DictWriter(fh, fieldnames=cols, extrasaction="ignore")
        w.writeheader()
        w.writerows(rows)
    return rows


def _discretizations_part(args, out: Path) -> tuple[list[dict], dict]:
    from studies.discretizations import SERIES, measure_series, references

    fine, est = references(SCENES["example1"], args.disc_ref_n, args.disc_ref_k, Path(args.cache))
    rows = measure_series(fine, args.disc_ns, args.disc_ks, extra=[("P1, order 1 (paper)", 128, 0.001)])
    ok = [r for r in rows if r["status"] == "converged"]
    for label in SERIES:
        sub = [r for r in ok if r["series"] == label]
        front = set(pareto([(r["loop_seconds"], r["error"]) for r in sub]))
        for i, r in enumerate(sub):
            r["pareto_series"] = i in front
    front = set(pareto([(r["loop_seconds"], r["error"]) for r in ok]))
    for i, r in enumerate(ok):
        r["pareto_all"] = i in front
    with open(out / "work_precision_discretizations.csv", "w", newline="") as fh:
        w = csv.DictWriter(fh, fieldnames=DISC_COLUMNS, extrasaction="ignore")
        w.writeheader()
        w.writerows(rows)
    info = {"n": fine.n, "k": fine.k, "second": est, "seconds": fine.seconds}
    (out / "work_precision_reference.json").write_text(json.dumps(info, indent=1))
    return rows, info


def work_precision(args) -> int:
    """Methods (against the P1 reference) and discretizations (against the P2 / order 2 reference), one chart."""
    out = Path(args.output)
    out.mkdir(parents=True, exist_ok=True)
    if "methods" in args.parts:
        rows = _methods_part(args, out)
    else:  # the chart keeps the last measured methods
        rows = _read_rows(out / "work_precision.csv") if (out / "work_precision.csv").exists() else []
    if "discretizations" in args.parts:
        disc, info = _discretizations_part(args, out)
    else:
        disc = _read_rows(out / "work_precision_discretizations.csv")
        info = json.loads((out / "work_precision_reference.json").read_text())
    plt = pyplot("the work-precision chart")
    if plt is None:
        return 0
    ok = [r for r in rows if r["status"] == "converged"]
    failed = sorted({r["method"] for r in rows if r["status"] != "converged"})
    fig, axes = plt.subplots(1, 3, figsize=(19, 5.4))
    titles = {"error": "methods: Table 1 norm, max over levels (reached at t = 0: spatial)",
              "error_T": "methods: the same norm at t = T"}
    for ax, key in zip(axes, ("error", "error_T")):
        for label, marker in zip(dict.fromkeys(r["method"] for r in ok), "osD^vPX*"):
            sub = [r for r in ok if r["method"] == label]
            ax.loglog([r["seconds"] for r in sub], [r[key] for r in sub], marker, alpha=0.75, label=label)
        pf = sorted((r for r in ok if r[f"pareto_{key}"]), key=lambda r: r["seconds"])
        ax.loglog([r["seconds"] for r in pf], [r[key] for r in pf], "-", color="k", lw=1, label="Pareto front")
        for r in pf:
            ax.annotate(f"{r['method'].split('+')[-1][:9]} n={r['n']:g},k={r['k']:g}", (r["seconds"], r[key]),
                        fontsize=6, xytext=(3, 3), textcoords="offset points")
        ax.set_xlabel("wall time of the run (s)")
        ax.set_ylabel(r"$\|\varepsilon(u-u^{ref})\| + \|\zeta-\zeta^{ref}\|$")
        ax.set_title(titles[key] + f" (P1 reference n = {args.ref_n})", fontsize=8)
        ax.grid(True, which="both", alpha=0.3)
    axes[0].legend(fontsize=7)
    _draw_discretizations(axes[2], disc, info)
    fig.suptitle(f"Example 1 (mu = 1e-10). Methods: n = {', '.join(map(str, args.ns))}, k = {max(args.ks):g} ... "
                 f"{min(args.ks):g}" + (f"; failed, not drawn: {', '.join(failed)}" if failed else ""), fontsize=9)
    fig.tight_layout()
    fig.savefig(out / "work_precision.png", dpi=120)
    plt.close(fig)
    print(f"wrote {out / 'work_precision.png'} and its CSV files")
    return 0


def _draw_discretizations(ax, disc: list[dict], info: dict) -> None:
    ok = [r for r in disc if r["status"] == "converged"]
    grid = [r for r in ok if not (r["n"] == 128 and r["k"] == 0.001)]
    labels = list(dict.fromkeys(r["series"] for r in grid))
    for label, marker, color in zip(labels, "os^D", ("C0", "C1", "C2", "C3")):
        sub = sorted((r for r in grid if r["series"] == label), key=lambda r: r["loop_seconds"])
        ax.loglog([r["loop_seconds"] for r in sub], [r["error"] for r in sub], marker, color=color, alpha=0.6,
                  label=label)
        pf = [r for r in sub if r["pareto_series"]]
        ax.loglog([r["loop_seconds"] for r in pf], [r["error"] for r in pf], "-", color=color, lw=1)
    for r in (r for r in ok if r["n"] == 128 and r["k"] == 0.001):
        ax.loglog([r["loop_seconds"]], [r["error"]], "kx", ms=9, label="paper's scheme, n = 128, k = 0.001")
    ax.axhline(8.289e-4, color="gray", ls="--", lw=0.8, label="8.3e-4 (the paper's best Table 1 entry)")
    ax.axvline(1.0, color="gray", ls=":", lw=0.8)
    best = [r for r in ok if r["error"] <= 8.289e-4 and r["loop_seconds"] <= 1.0]
    if best:
        r = min(best, key=lambda r: r["loop_seconds"])
        ax.annotate(f"{r['series']} n={r['n']:g}, k={r['k']:g}: {r['error']:.2e} in {r['loop_seconds']:.2f} s",
                    (r["loop_seconds"], r["error"]), fontsize=7, xytext=(5, -12), textcoords="offset points")
    ax.set_xlabel("time-loop wall time (s)")
    ax.set_title(f"discretizations against the P2 / order 2 reference (n = {info['n']:g}, k = {info['k']:g}; "
                 f"its own error ~ {info['second']['estimate']:.1e})", fontsize=8)
    ax.grid(True, which="both", alpha=0.3)
    ax.legend(fontsize=7)


def orders(args) -> int:
    """The order table: observed orders in h (P1, P2) and in k (orders 1 and 2), to orders.md and orders.json."""
    from studies.discretizations import order_table, orders_markdown, references

    out = Path(args.output)
    out.mkdir(parents=True, exist_ok=True)
    fine, est = references(SCENES["example1"], args.disc_ref_n, args.disc_ref_k, Path(args.cache))
    table = order_table(fine, SCENES["example1"], args.disc_ns, args.disc_ks, args.n_time)
    table["reference"] = {"n": fine.n, "k": fine.k, "second": est}
    (out / "orders.json").write_text(json.dumps(table, indent=1))
    (out / "orders.md").write_text(orders_markdown(table, args.n_time))
    print((out / "orders.md").read_text())
    return 0


def estimator(args) -> int:
    """The residual estimator's calibration at t = 0, to estimator.md and estimator.json."""
    from studies import estimator as estimator_study

    return estimator_study.run(SCENES["example1"], Path(args.output), args.ref_n, args.p1, args.p2)


def _quiet() -> None:
    """Worker processes: the form compiler's build chatter off, as in the CLI."""
    import logging

    import ffcx  # noqa: F401  (calls logging.basicConfig() on import)

    for h in logging.getLogger().handlers:
        h.setLevel(logging.WARNING)


def _run_groups(fn, groups: list[tuple], jobs: int) -> list[dict]:
    rows: list[dict] = []
    t0 = time.perf_counter()
    if jobs <= 1:
        results = map(fn, groups)
    else:
        pool = ProcessPoolExecutor(max_workers=jobs, mp_context=get_context("spawn"), initializer=_quiet)
        results = pool.map(fn, groups)
    for i, res in enumerate(results, start=1):
        rows.extend(res)
        print(f"[{i}/{len(groups)}] {res[0]['scene']} mu={res[0]['mu']:g} {res[0]['method']}...: "
              f"{sum(r['status'] == 'converged' for r in res)}/{len(res)} converged ({time.perf_counter() - t0:.0f} s)",
              flush=True)
    return rows


def _usage(parse):
    """An argparse type from a parser of one item that raises ValueError: a bad item is a usage error (exit 2)."""
    def parse_or_usage(item: str):
        try:
            return parse(item)
        except ValueError as exc:
            raise argparse.ArgumentTypeError(str(exc)) from None

    return parse_or_usage


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(prog="python -m studies study",
                                description="the studies behind the published figures: stability map, work-precision "
                                            "chart, orders, estimator, Table 1 variants, tolerance runs")
    sub = p.add_subparsers(dest="which", required=True)
    helps = {"stability": "where each displacement method fails, over mu, k and two meshes (a heat map per method)",
             "work-precision": "error against wall time per method and discretization",
             "orders": "the observed orders in h and in k"}
    for name, ref_n in (("stability", 32), ("work-precision", 128), ("orders", 128)):
        s = sub.add_parser(name, help=helps[name])
        s.add_argument("--output", default=str(ROOT / "benchmarks" / "results"), help="where the CSV and charts go")
        s.add_argument("--cache", default=str(ROOT / "benchmarks" / "cache"), help="cached reference runs")
        s.add_argument("--ref-n", type=int, default=ref_n, help="mesh (n cells across) of the fine reference")
        s.add_argument("--ref-k", type=float, default=0.0005, help="time step of the fine reference")
        s.add_argument("--jobs", type=int, default=2, help="runs in parallel")
    st, wp, od = sub.choices["stability"], sub.choices["work-precision"], sub.choices["orders"]
    for parser in (wp, od):  # the discretization series and their P2 / order 2 reference
        parser.add_argument("--disc-ref-n", type=int, default=256)
        parser.add_argument("--disc-ref-k", type=float, default=0.0025)
        parser.add_argument("--disc-ns", type=int, nargs="+", default=[8, 16, 32, 64])
        parser.add_argument("--disc-ks", type=float, nargs="+", default=[0.1, 0.05, 0.025, 0.0125])
    wp.add_argument("--parts", nargs="+", default=["methods", "discretizations"], choices=["methods", "discretizations"],
                    help="what to measure (the chart redraws the other part from its CSV)")
    od.add_argument("--n-time", type=int, default=16, help="the mesh of the orders in k")
    st.add_argument("--scenes", nargs="+", default=list(SCENES), choices=list(SCENES))
    st.add_argument("--mus", type=float, nargs="+", default=MUS)
    st.add_argument("--ks", type=float, nargs="+", default=KS)
    st.add_argument("--ns", type=int, nargs="+", default=NS)
    st.add_argument("--methods", nargs="+", choices=list(VARIANTS),
                    default=["newton", "newton_energy", "newton_condensed", "penalty_duality", "fixed_point",
                             "newton+semi_implicit_damage"])
    st.add_argument("--max-it", type=int, default=200, help="iteration limit per step, for every method")
    st.add_argument("--adaptive-ref-k", type=float, default=None,
                    help="the step of the same-mesh reference of the adaptive cells (default: the smallest k / 4)")
    wp.add_argument("--ks", type=float, nargs="+", default=[0.1, 0.05, 0.02, 0.01, 0.005, 0.002, 0.001])
    wp.add_argument("--ns", type=int, nargs="+", default=[8, 16, 32, 64])
    wp.add_argument("--methods", nargs="+", default=list(VARIANTS), choices=list(VARIANTS))
    es = sub.add_parser("estimator", help="calibrate the residual estimator at t = 0 (Example 1)")
    es.add_argument("--output", default=str(ROOT / "benchmarks" / "results"))
    es.add_argument("--ref-n", type=int, default=256, help="mesh of the P2 reference")
    es.add_argument("--p1", type=int, nargs="*", default=[8, 16, 32, 64, 128])
    es.add_argument("--p2", type=int, nargs="*", default=[8, 16, 32, 64])
    tv = sub.add_parser("table1-variants", help="which measurement reproduces the paper's Table 1 (issue 17)")
    tv.add_argument("config", nargs="?", default=str(SCENES["example1"]), help="the scene (default: Example 1)")
    tv.add_argument("--output", default=str(ROOT / "benchmarks" / "results"))
    tv.add_argument("--cache", default=str(ROOT / "benchmarks" / "cache"))
    tv.add_argument("--ref-n", type=int, default=256)
    tv.add_argument("--ref-k", type=float, default=0.0005)
    tv.add_argument("--ns", type=int, nargs="+", help="default: the paper's 4 ... 128")
    tv.add_argument("--ks", type=float, nargs="+", help="default: the paper's 0.05 ... 0.001")
    tv.add_argument("--variants", nargs="+", default=list(T1_VARIANTS), choices=list(T1_VARIANTS), metavar="NAME",
                    help="the named variants to report (default: all of " + ", ".join(T1_VARIANTS) + "); "
                    "each needs its runs (u0, diagonal)")
    tv.add_argument("--no-search", action="store_true", help="skip the search over every combination of the "
                    "measurement-only choices")
    to = sub.add_parser("tolerance", help="tolerance runs against a fine reference and the cheapest uniform choice "
                        "(issue 14)")
    from studies.tolerance import SCENES as TOL_SCENES
    from studies.tolerance import TOLS, scene_ref_tol, scene_ref_uniform

    to.add_argument("--output", default=str(ROOT / "benchmarks" / "results"))
    to.add_argument("--scenes", nargs="+", default=list(TOL_SCENES), choices=list(TOL_SCENES))
    to.add_argument("--tols", type=float, nargs="+", default=list(TOLS))
    to.add_argument("--ref-tol", type=float, default=1e-4, help="tolerance of the P2 reference run")
    to.add_argument("--scene-ref-tol", nargs="+", metavar="NAME=TOL", default=[], type=_usage(scene_ref_tol),
                    help="a scene's own reference tolerance where --ref-tol is out of reach (stated in the output)")
    to.add_argument("--scene-ref-uniform", nargs="+", metavar="NAME=N:STEPS", default=[], type=_usage(scene_ref_uniform),
                    help="a scene's reference as a uniform P2, second-order run (n cells across, k = T/STEPS), where "
                    "a tolerance reference is out of reach (stated in the output)")
    to.add_argument("--levels", type=int, default=6, help="uniform meshes per series (n = 4, 8, ... or r = 0, 1, ...)")
    to.add_argument("--steps", type=int, nargs="+", default=[10, 20, 40, 80], help="uniform steps per run (T / k)")
    to.add_argument("--no-sweep", action="store_true", help="leave out the uniform sweep (the verified uniform "
                    "alternative of every tolerance run is measured all the same)")
    args = p.parse_args(argv)
    if args.which == "tolerance":
        from studies.tolerance import main as tolerance_main

        return tolerance_main(args)
    if args.which == "table1-variants":
        from studies.table1_variants import main as table1_variants

        args.argv = list(argv if argv is not None else sys.argv[2:])
        return table1_variants(args)
    return {"stability": stability, "work-precision": work_precision, "orders": orders,
            "estimator": estimator}[args.which](args)
