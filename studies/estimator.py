"""Calibration of the residual estimator (solver/physics/estimator.py) on Example 1's t = 0 problem.

The elastic contact problem at t = 0 is solved on uniform meshes with P1 and P2 and
compared with a P2 solution on a much finer mesh of the same family (nested, so the
coarse solutions are interpolated onto it exactly). For each run the study records the
estimate η, the error ‖ε(u_ref − u_h)‖, their ratio C = error / η (the constant the
tolerance control will use, per degree), the observed rates in h of both, and where η²
sits: the share within r < 0.1 of the corners (1, 0) (loaded edge meets the contact edge)
and (1, 1) (loaded edge meets the free top).
"""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np

CORNERS = {"(1, 0)": (1.0, 0.0), "(1, 1)": (1.0, 1.0)}


def _level0(cfg_path: Path, n: int, degree: int):
    from mpi4py import MPI

    from solver.config import load
    from solver.run.model import build_model
    from solver.run.stepper import Stepper

    cfg = load(cfg_path, [f"mesh.nx={n}", f"mesh.ny={n}", "time.k=1.0", "time.T=1.0", "output.xdmf=false",
                          f"discretization.u_degree={degree}"])
    model = build_model(cfg, MPI.COMM_SELF)
    Stepper(model).step(0)
    return model


def _error_against(ref):
    """error(model) = ||eps(u_ref - u_h)|| on the reference's space, u_h interpolated there exactly (the meshes
    nest): the strain Gram matrix and the reference's dof points are built once."""
    import ufl
    from dolfinx import fem
    from dolfinx.fem import petsc as fpetsc

    from solver.mesh.transfer import interpolation_matrix, petsc_to_scipy

    V = ref.u.function_space
    du, w = ufl.TrialFunction(V), ufl.TestFunction(V)
    gram = fpetsc.assemble_matrix(fem.form(ufl.inner(ufl.sym(ufl.grad(du)), ufl.sym(ufl.grad(w))) * ufl.dx))
    gram.assemble()
    gram = petsc_to_scipy(gram)
    points = V.tabulate_dof_coordinates()[:, :2]
    u_ref = ref.u.x.array.copy()

    def error(model) -> float:
        P = interpolation_matrix(model.u.function_space, points)
        e = u_ref - (P @ model.u.x.array.reshape(-1, 2)).ravel()
        return float(np.sqrt(max(e @ (gram @ e), 0.0)))

    return error


def calibrate(cfg_path: Path, runs: list[tuple[int, int]], ref_n: int, log=print) -> dict:
    """η and the error at t = 0 for every (degree, n) of ``runs`` against a P2 solve at ``ref_n``."""
    from solver.physics.estimator import estimator_for

    ref = _level0(cfg_path, ref_n, 2)
    error_of = _error_against(ref)
    ref_estimate = estimator_for(ref).total()
    log(f"reference P2 n={ref_n}: eta = {ref_estimate:.4g}")
    rows = []
    for degree, n in runs:
        model = _level0(cfg_path, n, degree)
        est = estimator_for(model)
        eta2 = est.cells()
        eta = est.total(eta2)
        error = error_of(model)
        mesh = model.geo.mesh
        centres = _cell_centres(mesh, len(eta2))
        shares = {name: float(eta2[np.hypot(*(centres - np.array(c)).T) < 0.1].sum() / eta2.sum())
                  for name, c in CORNERS.items()}
        rows.append({"degree": degree, "n": n, "dofs": int(model.u.x.array.size), "eta": eta, "error": error,
                     "C": error / eta, "share_near": shares})
        log(f"P{degree} n={n:4d}: eta {eta:.4e}  error {error:.4e}  C = error/eta {error / eta:.4e}  "
            + "  ".join(f"eta^2 near {k}: {v:.2f}" for k, v in shares.items()))
    for degree in sorted({r["degree"] for r in rows}):
        mine = [r for r in rows if r["degree"] == degree]
        for a, b in zip(mine, mine[1:]):
            b["rate_eta"] = float(np.log(a["eta"] / b["eta"]) / np.log(b["n"] / a["n"]))
            b["rate_error"] = float(np.log(a["error"] / b["error"]) / np.log(b["n"] / a["n"]))
    return {"reference": {"degree": 2, "n": ref_n, "eta": ref_estimate}, "runs": rows}


def adapted_series(cfg_path: Path, degree: int, theta: float, max_dofs: int, n0: int = 4, ref_refinements: int = 2,
                   log=print) -> dict:
    """Example 1 at t = 0 on meshes adapted by Dörfler marking (θ) from a uniform n0 mesh, until the
    displacement has more than ``max_dofs`` dofs; each error against P2 on the last mesh refined
    uniformly ``ref_refinements`` times (every mesh of the series nests in it: the transfer is exact)."""
    from mpi4py import MPI

    from solver.config import load
    from solver.mesh.adapt import refine, refine_uniformly
    from solver.physics.estimator import dorfler, estimator_for
    from solver.run.model import build_model
    from solver.run.stepper import Stepper

    cfg = load(cfg_path, [f"mesh.nx={n0}", f"mesh.ny={n0}", "time.k=1.0", "time.T=1.0", "output.xdmf=false",
                          f"discretization.u_degree={degree}"])
    comm = MPI.COMM_SELF
    geo, solutions = None, []
    while True:
        model = build_model(cfg, comm, geo)
        Stepper(model).step(0)
        est = estimator_for(model)
        eta2 = est.cells()
        solutions.append((model, est.total(eta2)))
        dofs = model.u.x.array.size
        log(f"P{degree} adapted: {model.geo.num_cells()} cells, {dofs} dofs, eta {solutions[-1][1]:.4e}")
        if dofs > max_dofs:
            break
        geo = refine(model.geo, np.flatnonzero(dorfler(eta2, theta, comm)))
    fine = model.geo
    for _ in range(ref_refinements):
        fine = refine_uniformly(fine)
    ref_cfg = load(cfg_path, [f"mesh.nx={n0}", f"mesh.ny={n0}", "time.k=1.0", "time.T=1.0", "output.xdmf=false",
                              "discretization.u_degree=2"])
    ref = build_model(ref_cfg, comm, fine)
    Stepper(ref).step(0)
    ref_eta = estimator_for(ref).total()
    error_of = _error_against(ref)
    rows = []
    for model, eta in solutions:
        error = error_of(model)
        rows.append({"cells": model.geo.num_cells(), "dofs": int(model.u.x.array.size), "eta": eta, "error": error,
                     "C": error / eta})
    log(f"P{degree} adapted reference: P2 on the last mesh refined {ref_refinements} times, {ref.u.x.array.size} dofs, "
        f"eta {ref_eta:.4e}")
    return {"degree": degree, "theta": theta, "n0": n0, "runs": rows,
            "reference": {"dofs": int(ref.u.x.array.size), "eta": ref_eta, "refinements": ref_refinements}}


def fitted_rate(rows: list[dict], key: str = "error", last: int = 4) -> float:
    """r in key ~ dofs^-r, least squares over the last ``last`` runs."""
    x = np.log([r["dofs"] for r in rows[-last:]])
    y = np.log([r[key] for r in rows[-last:]])
    return float(-np.polyfit(x, y, 1)[0])


def _cell_centres(mesh, n_cells: int) -> np.ndarray:
    x = mesh.geometry.x[:, :2]
    nodes = mesh.geometry.dofmap.array.reshape(-1, mesh.topology.dim + 1)[:n_cells]
    return x[nodes].mean(axis=1)


def markdown(result: dict) -> str:
    ref = result["reference"]
    lines = [f"## Residual estimator at t = 0 (Example 1), against P2 at n = {ref['n']}", "",
             "| space | n | u dofs | eta | error ‖ε(u_ref − u_h)‖ | C = error / eta | rate eta | rate error "
             "| eta² near (1, 0) | eta² near (1, 1) |", "|---|---|---|---|---|---|---|---|---|---|"]
    for r in result["runs"]:
        rate = (f"{r['rate_eta']:.2f} | {r['rate_error']:.2f}" if "rate_eta" in r else "— | —")
        lines.append(f"| P{r['degree']} | {r['n']} | {r['dofs']} | {r['eta']:.4e} | {r['error']:.4e} | {r['C']:.4e} "
                     f"| {rate} | {r['share_near']['(1, 0)']:.2f} | {r['share_near']['(1, 1)']:.2f} |")
    lines += ["", "Near: cell centres within r < 0.1 of the corner. The reference's own estimate: "
              f"eta = {ref['eta']:.4e}.", ""]
    uniform = {d: [r for r in result["runs"] if r["degree"] == d] for d in (1, 2)}
    for series in result.get("adapted", []):
        d = series["degree"]
        lines += [f"## P{d} on meshes adapted by Dörfler marking (θ = {series['theta']}) from n = {series['n0']}", "",
                  "| cells | u dofs | eta | error | C = error / eta |", "|---|---|---|---|---|"]
        lines += [f"| {r['cells']} | {r['dofs']} | {r['eta']:.4e} | {r['error']:.4e} | {r['C']:.4e} |" for r in series["runs"]]
        lines += ["", reference_note(series, uniform[2] or [s for s in result["adapted"] if s["degree"] == 2][0]["runs"])
                  + " Error ~ dofs^-r over the last 4 runs: "
                  f"adapted r = {fitted_rate(series['runs']):.2f}, uniform r = {fitted_rate(uniform[d]):.2f} "
                  f"(eta: {fitted_rate(series['runs'], 'eta'):.2f} and {fitted_rate(uniform[d], 'eta'):.2f}).", ""]
    return "\n".join(lines)


def reference_note(series: dict, p2_runs: list[dict]) -> str:
    """What the adapted series' reference (P2 on its last mesh, refined) is worth: its own error, estimated as its
    eta times P2's C = error / eta (measured on the finest of ``p2_runs``: the reference is a P2 solution, so
    P2's constant, not the series' own), against the last adapted run's error."""
    rr, last, c2 = series["reference"], series["runs"][-1], p2_runs[-1]["C"]
    own = rr["eta"] * c2
    times = {1: "once", 2: "twice"}.get(rr["refinements"], f"{rr['refinements']} times")
    return (f"Reference: P2 on the last mesh refined uniformly {times} ({rr['dofs']} dofs); its "
            f"estimate eta = {rr['eta']:.3e} times P2's C = error / eta = {c2:.3e} (measured at {p2_runs[-1]['dofs']} "
            f"dofs) puts its own error at about {own:.1e}, {100 * own / last['error']:.1f} % of the last adapted "
            f"run's error {last['error']:.3e}.")


def run(cfg_path: Path, out: Path, ref_n: int, p1: list[int], p2: list[int], theta: float = 0.5,
        adapt_dofs: tuple[int, int] = (15000, 8000)) -> int:
    """Calibration on uniform meshes, then the adapted series of both degrees; to estimator.md/.json."""
    out.mkdir(parents=True, exist_ok=True)
    result = calibrate(cfg_path, [(1, n) for n in p1] + [(2, n) for n in p2], ref_n)
    result["adapted"] = [adapted_series(cfg_path, 1, theta, adapt_dofs[0], ref_refinements=1),
                         adapted_series(cfg_path, 2, theta, adapt_dofs[1], ref_refinements=2)]
    (out / "estimator.json").write_text(json.dumps(result, indent=1))
    (out / "estimator.md").write_text(markdown(result))
    print(markdown(result))
    return 0
