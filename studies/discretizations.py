"""Accuracy per second of the discretizations: P1/P2 in space and order 1/2 in time on Example 1.

Every run is measured against one fine reference computed with P2 and the second-order
scheme (:class:`reference.FineReference`), in the paper's norm (max over levels of
||eps(u - u_ref)|| + ||zeta - zeta_ref||), and timed by its time loop (the sum of its
rows' wall times: set-up and form compilation excluded, level 0's factorizations
included). The reference's own error is estimated from a second, coarser reference.

- :func:`measure_series`: the work-precision points of each series (``study work-precision``);
- :func:`order_table`: observed orders in h (P1, P2) and in k (order 1, order 2) (``study orders``).
"""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np

SERIES = {  # label -> scene overrides
    "P1, order 1 (paper)": ["discretization.u_degree=1", "time.order=1"],
    "P1, order 2": ["discretization.u_degree=1", "time.order=2"],
    "P2, order 1": ["discretization.u_degree=2", "time.order=1"],
    "P2, order 2": ["discretization.u_degree=2", "time.order=2"],
}
REFERENCE = ["discretization.u_degree=2", "time.order=2"]


def slope(x, y) -> float:
    """Least-squares slope of log y against log x (NaN with fewer than two points)."""
    x, y = np.asarray(x, float), np.asarray(y, float)
    ok = (x > 0) & (y > 0) & np.isfinite(y)
    return float(np.polyfit(np.log(x[ok]), np.log(y[ok]), 1)[0]) if ok.sum() > 1 else float("nan")


def references(scene: Path, n_ref: int, k_ref: float, cache: Path, log=print):
    """The fine reference and a second one at (n_ref/2, 2 k_ref); returns (fine, estimate of its own error)."""
    from studies.reference import FineReference

    fine = FineReference(scene, REFERENCE, n_ref, k_ref, cache, log=log)
    second = fine.measure(REFERENCE, n_ref // 2, 2 * k_ref)
    # the coarser reference's error is ||second - fine|| + the fine one's; with a spatial rate of about 1
    # (the corner singularities) the fine reference's own error is about that difference again
    return fine, {"n": n_ref // 2, "k": 2 * k_ref, "difference": second["error"], "estimate": second["error"]}


def measure_series(fine, ns, ks, labels=None, extra: list[tuple[str, int, float]] = (), log=print) -> list[dict]:
    """Error and loop time of every (series, n, k); ``extra`` adds single points (label, n, k)."""
    rows = []
    points = [(label, n, k) for label in (labels or SERIES) for n in ns for k in ks] + list(extra)
    for label, n, k in points:
        rec = fine.measure(SERIES[label], n, k)
        rec["series"] = label
        rec["status"] = "converged" if rec.pop("failure") is None else "failed"
        rows.append(rec)
        log(f"{label:20s} n={n:3d} k={k:<7g} error {rec['error']:.3e} loop {rec['loop_seconds']:.3f} s")
    return rows


def order_table(fine, scene: Path, ns, ks, n_time: int, log=print) -> dict:
    """Observed orders: in h (P1, P2; second order at the smallest k, against ``fine``) and in k (orders 1 and 2
    on the mesh n_time, against the same discretization at k_min / 8: the time error alone)."""
    from studies.reference import FineReference

    out: dict = {"h": {}, "k": {}}
    k_small = min(ks)
    for label in ("P1, order 2", "P2, order 2"):
        errs = [fine.measure(SERIES[label], n, k_small)["error"] for n in ns]
        out["h"][label.split(",")[0]] = {"ns": list(ns), "errors": errs, "rate": slope([1 / n for n in ns], errs)}
        log(f"h: {label}: " + " ".join(f"{e:.3e}" for e in errs))
    for label in SERIES:
        same = FineReference(scene, SERIES[label], n_time, k_small / 8, fine.cache, log=log)
        errs = [same.measure(SERIES[label], n_time, k)["error"] for k in ks]
        rates = [math.log2(a / b) for a, b in zip(errs, errs[1:])]
        out["k"][label] = {"ks": list(ks), "errors": errs, "rates": rates, "rate": slope(ks, errs)}
        log(f"k: {label}: " + " ".join(f"{e:.3e}" for e in errs) + " rates " + " ".join(f"{r:.2f}" for r in rates))
    return out


def orders_markdown(table: dict, n_time: int) -> str:
    lines = ["# Observed orders (Example 1, the paper's norm)", "",
             "In h: second order in time at the smallest k, against the P2 / order 2 reference.", "",
             "| space | " + " | ".join(f"n = {n}" for n in next(iter(table["h"].values()))["ns"]) + " | rate in h |",
             "|---|" + "---|" * (len(next(iter(table["h"].values()))["ns"]) + 1)]
    for label, row in table["h"].items():
        lines.append(f"| {label} | " + " | ".join(f"{e:.2e}" for e in row["errors"]) + f" | {row['rate']:.2f} |")
    ks = next(iter(table["k"].values()))["ks"]
    lines += ["", f"In k: on the mesh n = {n_time}, against the same discretization at k = {min(ks) / 8:g} "
              "(the time error alone); the rate between successive k.", "",
              "| scheme | " + " | ".join(f"k = {k:g}" for k in ks) + " | rates | fitted |",
              "|---|" + "---|" * (len(ks) + 2)]
    for label, row in table["k"].items():
        lines.append(f"| {label} | " + " | ".join(f"{e:.2e}" for e in row["errors"]) + " | "
                     + ", ".join(f"{r:.2f}" for r in row["rates"]) + f" | {row['rate']:.2f} |")
    return "\n".join(lines) + "\n"
