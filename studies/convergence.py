"""Convergence study of the paper's Table 1 (``python -m studies convergence CONFIG``).

A reference solution (default n = 256, k = 0.0005) is stored at every time level that
a coarse step needs; each coarse solution (n, k) is then compared with it on the fine
mesh at the coarse time levels:

    error = max_n ( ||eps(u_n^ref - u_n^hk)||_L2 + ||zeta_n^ref - zeta_n^hk||_L2 ).

The coarse rectangles nest in the fine one (same diagonal pattern, n divides n_ref),
so P1 fields are transferred exactly by index arithmetic on the structured grid, with
no point search. The norms use the fine mesh's matrices (eps:eps and mass), assembled
once. Runs serially.
"""

from __future__ import annotations

import argparse
import csv
import hashlib
import json
import os
import time
from pathlib import Path

import numpy as np
import scipy.sparse as sp

from solver.errors import SolveFailure
from solver.mesh.transfer import petsc_to_scipy
from solver.post.charts import pyplot

PAPER_NS = (4, 8, 16, 32, 64, 128)
PAPER_KS = (0.05, 0.02, 0.01, 0.005, 0.002, 0.001)
# Table 1 of the paper, as printed (rows n, columns k).
PAPER_TABLE1 = {
    4: (6.779e-2, 6.665e-2, 6.628e-2, 6.610e-2, 6.610e-2, 6.596e-2),
    8: (3.204e-2, 3.032e-2, 2.978e-2, 2.951e-2, 2.935e-2, 2.930e-2),
    16: (1.574e-2, 1.353e-2, 1.285e-2, 1.254e-2, 1.235e-2, 1.299e-2),
    32: (9.222e-3, 6.560e-3, 5.757e-3, 5.390e-3, 5.187e-3, 5.123e-3),
    64: (6.767e-3, 3.793e-3, 2.863e-3, 2.429e-3, 2.197e-3, 2.128e-3),
    128: (5.879e-3, 2.682e-3, 1.671e-3, 1.186e-3, 9.101e-4, 8.289e-4),
}


def paper_error(n: int, k: float) -> float | None:
    row = PAPER_TABLE1.get(n)
    for kk, v in zip(PAPER_KS, row or ()):
        if abs(kk - k) < 1e-12:
            return v
    return None


# ----------------------------------------------------------------------------
# Exact transfer between nested structured rectangles
# ----------------------------------------------------------------------------


def grid_order(coords: np.ndarray, corners, n: int) -> np.ndarray:
    """For P1 dof coordinates of an n x n rectangle: the grid index j (n+1) + i of each dof."""
    (x0, y0), (x1, y1) = corners
    i = np.rint((coords[:, 0] - x0) / (x1 - x0) * n).astype(np.int64)
    j = np.rint((coords[:, 1] - y0) / (y1 - y0) * n).astype(np.int64)
    return j * (n + 1) + i


def prolongation(nc: int, nf: int, diagonal: str) -> sp.csr_matrix:
    """P1 interpolation from the nc-grid to the nf-grid (grid numbering), exact for nested meshes."""
    if nf % nc:
        raise ValueError(f"n = {nc} does not divide the reference n = {nf}: the meshes do not nest")
    if diagonal not in ("right", "left"):
        raise ValueError(f"mesh.diagonal = {diagonal!r}: the exact transfer supports 'right' and 'left'")
    r = nf // nc
    row, col = np.divmod(np.arange((nf + 1) ** 2), nf + 1)
    ci, cj = np.minimum(col // r, nc - 1), np.minimum(row // r, nc - 1)
    xi, eta = (col - ci * r) / r, (row - cj * r) / r

    def node(di, dj):
        return (cj + dj) * (nc + 1) + ci + di

    v00, v10, v01, v11 = node(0, 0), node(1, 0), node(0, 1), node(1, 1)
    if diagonal == "right":  # triangles {00, 10, 11} (xi >= eta) and {00, 11, 01}
        low = xi >= eta
        cols = np.where(low[:, None], np.c_[v00, v10, v11], np.c_[v00, v01, v11])
        w = np.where(low[:, None], np.c_[1 - xi, xi - eta, eta], np.c_[1 - eta, eta - xi, xi])
    else:  # "left": triangles {00, 10, 01} (xi + eta <= 1) and {10, 11, 01}
        low = xi + eta <= 1
        cols = np.where(low[:, None], np.c_[v00, v10, v01], np.c_[v10, v11, v01])
        w = np.where(low[:, None], np.c_[1 - xi - eta, xi, eta], np.c_[1 - eta, xi + eta - 1, 1 - xi])
    rows = np.repeat(np.arange((nf + 1) ** 2), 3)
    P = sp.csr_matrix((w.ravel(), (rows, cols.ravel())), shape=((nf + 1) ** 2, (nc + 1) ** 2))
    P.eliminate_zeros()
    return P


class Fields:
    """Grid-ordered views of a model's u (nodes x 2) and zeta (nodes)."""

    def __init__(self, model, n: int) -> None:
        corners = model.cfg.mesh.corners
        V = model.u.function_space
        coords = V.tabulate_dof_coordinates()
        self.u_order = grid_order(coords, corners, n)  # dof node -> grid index
        self.model = model
        self.n = n
        if model.damage is not None:
            self.z_order = grid_order(model.damage.V.tabulate_dof_coordinates(), corners, n)

    def u(self) -> np.ndarray:
        out = np.empty(((self.n + 1) ** 2, 2))
        out[self.u_order] = self.model.u.x.array.reshape(-1, 2)
        return out

    def zeta(self) -> np.ndarray:
        out = np.empty((self.n + 1) ** 2)
        if self.model.damage is None:
            out[:] = self.model.cfg.damage.zeta0
        else:
            out[self.z_order] = self.model.damage.zeta.x.array
        return out


# ----------------------------------------------------------------------------
# The study
# ----------------------------------------------------------------------------


def _needed_levels(ks, k_ref: float, steps_ref: int) -> np.ndarray:
    mults = []
    for k in ks:
        m = k / k_ref
        if abs(m - round(m)) > 1e-9:
            raise ValueError(f"k = {k} is not a multiple of the reference k = {k_ref}")
        mults.append(int(round(m)))
    levels = np.arange(steps_ref + 1)
    return levels[np.any([levels % m == 0 for m in mults], axis=0)]


def reference(cfg_path: Path, n_ref: int, k_ref: float, ks, cache: Path, overrides: list[str]):
    """Run (or load from the cache) the reference solution at the needed levels."""
    from mpi4py import MPI

    from solver.config import dumps, load
    from solver.io.results import run
    from solver.run.model import build_model

    cfg = load(cfg_path, [*overrides, f"mesh.nx={n_ref}", f"mesh.ny={n_ref}", f"time.k={k_ref}", "output.xdmf=false"])
    levels = _needed_levels(ks, k_ref, cfg.time.steps)
    key = hashlib.sha256((dumps(cfg).split("\n", 1)[1] + repr(levels.tolist())).encode()).hexdigest()[:16]
    cache.mkdir(parents=True, exist_ok=True)
    path = cache / f"reference-{n_ref}-{k_ref}-{key}.npy"
    model = build_model(cfg, MPI.COMM_SELF)
    nodes = (n_ref + 1) ** 2
    info = {"n": n_ref, "k": k_ref, "levels": len(levels), "cached": path.exists()}
    if path.exists():
        data = np.load(path, mmap_mode="r")
    else:
        fields = Fields(model, n_ref)
        tmp = path.with_suffix(f".{os.getpid()}.tmp.npy")  # concurrent builders each write their own, rename wins
        data = np.lib.format.open_memmap(tmp, mode="w+", dtype=np.float64, shape=(len(levels), nodes, 3))
        slot = {int(m): i for i, m in enumerate(levels)}

        def store(row):
            i = slot.get(int(row["step"]))
            if i is not None:
                data[i, :, :2] = fields.u()
                data[i, :, 2] = fields.zeta()

        t0 = time.perf_counter()
        run(model, on_step=store)
        info["seconds"] = time.perf_counter() - t0
        data.flush()
        del data
        os.replace(tmp, path)
        data = np.load(path, mmap_mode="r")
    times = levels * k_ref
    return model, data, times, info


class Reference:
    """A reference solution and what comparing with it needs (fine-mesh norm matrices, levels)."""

    def __init__(self, cfg_path: Path, n_ref: int, k_ref: float, ks, cache: Path, overrides: list[str]) -> None:
        import dolfinx.fem.petsc  # noqa: F401
        import ufl
        from dolfinx import fem

        self.cfg_path, self.overrides, self.n, self.k = Path(cfg_path), list(overrides), n_ref, k_ref
        self.model, self.data, self.times, self.info = reference(cfg_path, n_ref, k_ref, ks, cache, overrides)
        self.diagonal = self.model.cfg.mesh.diagonal
        V = self.model.u.function_space
        du, w = ufl.TrialFunction(V), ufl.TestFunction(V)
        E = fem.petsc.assemble_matrix(fem.form(ufl.inner(ufl.sym(ufl.grad(du)), ufl.sym(ufl.grad(w))) * ufl.dx))
        E.assemble()
        Z = fem.FunctionSpace(self.model.geo.mesh, ("CG", 1))
        z, xi = ufl.TrialFunction(Z), ufl.TestFunction(Z)
        Mz = fem.petsc.assemble_matrix(fem.form(z * xi * ufl.dx))
        Mz.assemble()
        order = Fields(self.model, n_ref).u_order
        pu = np.empty(2 * len(order), dtype=np.int64)  # grid-ordered (node, comp) -> dof
        pu[2 * order] = 2 * np.arange(len(order))
        pu[2 * order + 1] = 2 * np.arange(len(order)) + 1
        z_order = grid_order(Z.tabulate_dof_coordinates(), self.model.cfg.mesh.corners, n_ref)
        pz = np.empty(len(z_order), dtype=np.int64)
        pz[z_order] = np.arange(len(z_order))
        self.pu, self.pz = pu, pz  # grid order -> dof (the variants of studies/table1_variants.py assemble more norms)
        self.strain_gram = petsc_to_scipy(E)[pu][:, pu].tocsr()
        self.mass_zeta = petsc_to_scipy(Mz)[pz][:, pz].tocsr()
        self.slot = {round(t / k_ref): i for i, t in enumerate(self.times)}
        self._P: dict[int, sp.csr_matrix] = {}

    def measure(self, extra: list[str], n: int, k: float) -> tuple[dict, list[dict]]:
        """Run the scene at (n, k) with ``extra`` overrides and compare with the reference at its levels.

        Returns the error record (over the levels computed, also when the run fails) and the rows.
        A run that stops (a :class:`~solver.errors.SolveFailure`) is not an error of the measurement:
        the record holds it as ``record["failure"]`` (None when the run reached T).
        """
        from mpi4py import MPI

        from solver.config import load
        from solver.io.results import run
        from solver.run.model import build_model

        if n not in self._P:
            self._P[n] = prolongation(n, self.n, self.diagonal)
        P = self._P[n]
        cfg = load(self.cfg_path, [*self.overrides, *extra, f"mesh.nx={n}", f"mesh.ny={n}", f"time.k={k}",
                                   "output.xdmf=false"])
        t0 = time.perf_counter()
        model = build_model(cfg, MPI.COMM_SELF)
        fields = Fields(model, n)
        errs, rows = [], []

        def compare(row):
            rows.append(row)
            i = self.slot[round(row["t"] / self.k)]
            du = (self.data[i, :, :2] - P @ fields.u()).ravel()
            dz = self.data[i, :, 2] - P @ fields.zeta()
            errs.append((row["t"], float(np.sqrt(du @ (self.strain_gram @ du))), float(np.sqrt(dz @ (self.mass_zeta @ dz)))))

        def record() -> dict:
            e = np.array(errs) if errs else np.zeros((1, 3))
            total = e[:, 1] + e[:, 2]
            m = int(np.argmax(total))
            return {"n": n, "k": k, "error": float(total[m]), "error_u": float(e[m, 1]), "error_zeta": float(e[m, 2]),
                    "max_error_u": float(e[:, 1].max()), "max_error_zeta": float(e[:, 2].max()),
                    "t_max": float(e[m, 0]), "error_t0": float(total[0]), "error_T": float(total[-1]),
                    "error_after_t0": float(total[1:].max()) if len(total) > 1 else float("nan"),
                    "seconds": time.perf_counter() - t0, "levels": len(errs)}

        failure = None
        try:
            run(model, on_step=compare)
        except SolveFailure as exc:
            failure = exc
        return {**record(), "failure": failure}, rows


def study(cfg_path: Path, ns, ks, n_ref: int, k_ref: float, cache: Path, overrides: list[str] | None = None,
          log=print) -> tuple[list[dict], dict]:
    """Errors of every (n, k) against the reference; returns the rows and the reference info."""
    ref = Reference(cfg_path, n_ref, k_ref, ks, cache, overrides or [])
    info = ref.info
    log(f"reference n={n_ref} k={k_ref}: {info['levels']} stored levels"
        + (" (from cache)" if info["cached"] else f" ({info['seconds']:.1f} s)"))
    rows = []
    for n in ns:
        for k in ks:
            rec, _ = ref.measure([], n, k)
            if rec["failure"] is not None:
                raise rec["failure"]
            pe = paper_error(n, k)
            rec.update({"paper_error": pe, "ratio": rec["error"] / pe if pe else None})
            rows.append(rec)
            log(f"n={n:4d} k={k:<7g} error {rec['error']:.4e} (u {rec['error_u']:.3e}, zeta {rec['error_zeta']:.3e}, "
                f"t={rec['t_max']:.3g})" + (f"  paper {pe:.4e}" if pe else ""))
    return rows, info


def rates(rows: list[dict]) -> dict:
    """Least-squares slopes of log(error) in log(h) (per k) and in log(k) (per n), and in log(h + k)."""
    ns = sorted({r["n"] for r in rows})
    ks = sorted({r["k"] for r in rows})
    err = {(r["n"], r["k"]): r["error"] for r in rows}

    def slope(x, y):
        return float(np.polyfit(np.log(x), np.log(y), 1)[0]) if len(x) > 1 else float("nan")

    out = {
        "h": {str(k): slope([1 / n for n in ns], [err[n, k] for n in ns]) for k in ks},
        "k": {str(n): slope(ks, [err[n, k] for k in ks]) for n in ns},
        "h_plus_k": slope([1 / r["n"] + r["k"] for r in rows], [r["error"] for r in rows]),
    }
    paper = [(1 / n + k, paper_error(n, k)) for n in ns for k in ks if paper_error(n, k)]
    if len(paper) > 1:
        out["paper_h_plus_k"] = slope(*zip(*paper))
    return out


def write(rows: list[dict], info: dict, out: Path, title: str) -> None:
    """table1.csv, table1.md (with the paper side by side and the rates), error_vs_hk.png."""
    out.mkdir(parents=True, exist_ok=True)
    with open(out / "table1.csv", "w", newline="") as fh:
        cols = ["n", "k", "error", "error_u", "error_zeta", "paper_error", "ratio", "t_max", "max_error_u",
                "max_error_zeta", "error_t0", "error_T", "error_after_t0", "seconds"]
        wr = csv.DictWriter(fh, fieldnames=cols, extrasaction="ignore")
        wr.writeheader()
        for r in rows:
            wr.writerow({c: ("" if r[c] is None else r[c]) for c in cols})
    rt = rates(rows)
    ns = sorted({r["n"] for r in rows})
    ks = sorted({r["k"] for r in rows}, reverse=True)
    by = {(r["n"], r["k"]): r for r in rows}
    md = [f"# {title}", "", f"Reference: n = {info['n']}, k = {info['k']}. Each cell: ours / paper (ratio).", "",
          "| n \\ k | " + " | ".join(f"{k:g}" for k in ks) + " |", "|---|" + "---|" * len(ks)]
    for n in ns:
        cells = []
        for k in ks:
            r = by.get((n, k))
            if r is None:
                cells.append("")
            elif r["paper_error"]:
                cells.append(f"{r['error']:.3e} / {r['paper_error']:.3e} ({r['ratio']:.2f})")
            else:
                cells.append(f"{r['error']:.3e}")
        md.append(f"| {n} | " + " | ".join(cells) + " |")
    md += ["", "The same errors split in time: at t = 0 (the elastic contact problem, no time error) / "
           "max over t > 0 / at t = T.", "", "| n \\ k | " + " | ".join(f"{k:g}" for k in ks) + " |",
           "|---|" + "---|" * len(ks)]
    for n in ns:
        md.append(f"| {n} | " + " | ".join(
            f"{by[n, k]['error_t0']:.2e} / {by[n, k]['error_after_t0']:.2e} / {by[n, k]['error_T']:.2e}"
            if (n, k) in by else "" for k in ks) + " |")
    md += ["", "Observed rates (least-squares slopes of log error):", "",
           "- in h, per k: " + ", ".join(f"k={k}: {v:.2f}" for k, v in rt["h"].items()),
           "- in k, per n: " + ", ".join(f"n={n}: {v:.2f}" for n, v in rt["k"].items()),
           f"- in h + k over all points: {rt['h_plus_k']:.2f}"
           + (f" (paper's points: {rt['paper_h_plus_k']:.2f})" if "paper_h_plus_k" in rt else ""), ""]
    (out / "table1.md").write_text("\n".join(md))
    (out / "rates.json").write_text(json.dumps(rt, indent=1))

    plt = pyplot("the convergence chart")
    if plt is None:
        return
    fig, ax = plt.subplots(figsize=(6, 4.5))
    x = np.array([1 / r["n"] + r["k"] for r in rows])
    ax.loglog(x, [r["error"] for r in rows], "o", label="this code")
    paper = [(1 / r["n"] + r["k"], r["paper_error"]) for r in rows if r["paper_error"]]
    if paper:
        ax.loglog(*zip(*paper), "x", color="k", label="paper, Table 1")
    xs = np.array([x.min(), x.max()])
    ax.loglog(xs, np.median([r["error"] / (1 / r["n"] + r["k"]) for r in rows]) * xs, "--", color="gray",
              label="slope 1")
    ax.set_xlabel("h + k  (h = 1/n)")
    ax.set_ylabel(r"$\max_n \|\varepsilon(u-u^{hk})\| + \|\zeta-\zeta^{hk}\|$")
    ax.set_title(title)
    ax.grid(True, which="both", alpha=0.3)
    ax.legend()
    fig.tight_layout()
    fig.savefig(out / "error_vs_hk.png", dpi=120)
    plt.close(fig)


def main(argv: list[str] | None = None) -> int:
    from mpi4py import MPI

    p = argparse.ArgumentParser(prog="python -m studies convergence", description="The paper's Table 1: errors against a reference.")
    p.add_argument("config", help="a rectangle scene (Example 1: configs/example1.toml)")
    p.add_argument("--ref-n", type=int, default=256)
    p.add_argument("--ref-k", type=float, default=0.0005)
    p.add_argument("--ns", type=int, nargs="+", default=list(PAPER_NS))
    p.add_argument("--ks", type=float, nargs="+", default=list(PAPER_KS))
    p.add_argument("--set", dest="overrides", action="append", default=[], metavar="SECTION.KEY=VALUE")
    p.add_argument("--output", default="benchmarks/results")
    p.add_argument("--cache", default="benchmarks/cache", help="where the reference solution is kept for reuse")
    args = p.parse_args(argv)
    if MPI.COMM_WORLD.size > 1:
        raise SystemExit("error: the convergence study runs in one process (its runs are small; the reference is serial)")
    t0 = time.perf_counter()
    rows, info = study(Path(args.config), args.ns, args.ks, args.ref_n, args.ref_k, Path(args.cache), args.overrides)
    write(rows, info, Path(args.output), f"Example 1: error against the reference (n={args.ref_n}, k={args.ref_k})")
    print(f"wrote {args.output}/table1.csv, table1.md, rates.json, error_vs_hk.png in {time.perf_counter() - t0:.0f} s")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
