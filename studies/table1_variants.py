"""Which measurement reproduces the paper's Table 1 (``python -m studies study table1-variants``; issue 17).

The paper prints max_n ||u_n - u_n^hk||_V + ||zeta_n - zeta_n^hk||_Y against a reference
(n = 256, k = 0.0005) but not how the two were brought together. A :class:`Measurement`
names one reading of its text:

- ``transfer``: ``prolong`` (the coarse solution on the fine mesh: ours) or ``restrict``
  (the reference interpolated onto the coarse mesh, the error measured there: the part of
  the reference finer than the coarse mesh drops out);
- ``level0``: whether the maximum includes the coarse level 0 (without it: t >= k);
- ``u_norm``: ``eps`` (||eps(.)||, the paper's V norm, full tensor inner product),
  ``eps_voigt`` (the shear strain counted once), ``eps_engineering`` (gamma_12 = 2 eps_12),
  ``h1_semi`` (||grad .||), ``h1`` (the full H1 norm); ``zeta_norm``: ``l2`` or ``h1``;
- ``sampling``: at the coarse levels (``coarse``), or at every stored reference level
  with the coarse solution held (``hold``: the last coarse level, u_n on [t_n, t_n+1);
  ``hold_next``: the next one, u_n on (t_n-1, t_n]) or linear in time (``interpolate``);
- ``combine``: the maximum of the sum (``max_sum``, the paper's formula) or the sum of the
  two maxima (``sum_max``);
- ``initial``: u_0 from the elastic contact problem (``elastic``, the paper's Remark 7) or
  u_0 = Pi^h u(0), the reference's u at t = 0 interpolated (``interpolant``, Corollary 9);
- ``diagonal``: the mesh diagonal of the reference and of the coarse meshes.

The last two change the runs; the others only the measurement, so one coarse run serves
them all: per (transfer, sampling) a series of six squared seminorms of the difference
(:data:`FORMS`) is kept, and every norm and combination is formed from it. Between coarse
levels the squared norms are expanded (Q(a - b) = Q(a) - 2 a.Qb + b.Qb, Q(a) of the
reference precomputed), so sampling every reference level costs dot products, not solves.
Runs serially, like the Table 1 study.
"""

from __future__ import annotations

import csv
import itertools
import json
import sys
import time
from collections.abc import Callable, Iterable
from dataclasses import asdict, dataclass, fields
from pathlib import Path

import numpy as np
import scipy.sparse as sp

from solver.errors import UsageError
from solver.mesh.transfer import petsc_to_scipy
from studies.convergence import PAPER_KS, PAPER_NS, Fields, Reference, paper_error, prolongation, rates

TRANSFERS = ("prolong", "restrict")
U_NORMS = ("eps", "eps_voigt", "eps_engineering", "h1_semi", "h1")
ZETA_NORMS = ("l2", "h1")
SAMPLINGS = ("coarse", "hold", "hold_next", "interpolate")
COMBINES = ("max_sum", "sum_max")
INITIALS = ("elastic", "interpolant")
DIAGONALS = ("right", "left")
CHOICES = {"transfer": TRANSFERS, "level0": (True, False), "u_norm": U_NORMS, "zeta_norm": ZETA_NORMS,
           "sampling": SAMPLINGS, "combine": COMBINES, "initial": INITIALS, "diagonal": DIAGONALS}

# The squared seminorms kept per sample: four of u (eps:eps, eps_12^2, grad:grad, u.u), two of zeta.
FORMS = ("eps", "shear", "grad", "l2u", "l2z", "gradz")
U_FORMS = 4
U_WEIGHTS = {"eps": (1, 0, 0, 0), "eps_voigt": (1, -1, 0, 0), "eps_engineering": (1, 2, 0, 0),
             "h1_semi": (0, 0, 1, 0), "h1": (0, 0, 1, 1)}
Z_WEIGHTS = {"l2": (1, 0), "h1": (1, 1)}


@dataclass(frozen=True)
class Measurement:
    """One reading of the paper's Table 1 error (the defaults: ours, the paper's stated norm)."""

    transfer: str = "prolong"
    level0: bool = True
    u_norm: str = "eps"
    zeta_norm: str = "l2"
    sampling: str = "coarse"
    combine: str = "max_sum"
    initial: str = "elastic"
    diagonal: str = "right"

    def __post_init__(self) -> None:
        for f in fields(self):
            if getattr(self, f.name) not in CHOICES[f.name]:
                raise UsageError(f"measurement {f.name} = {getattr(self, f.name)!r}: expected one of "
                                 + ", ".join(map(str, CHOICES[f.name])))

    @property
    def run_key(self) -> tuple[str, str]:
        """What the coarse runs depend on (the rest is measurement only)."""
        return self.initial, self.diagonal

    def label(self) -> str:
        """The choices that differ from the default, e.g. ``transfer=restrict+level0=False``."""
        default = Measurement()
        diff = [f"{f.name}={getattr(self, f.name)}" for f in fields(self) if getattr(self, f.name) != getattr(default, f.name)]
        return "+".join(diff) or "default"


# The named variants: each choice of the issue alone, and the combinations it suggests.
VARIANTS: dict[str, Measurement] = {
    "ours": Measurement(),
    "restrict": Measurement(transfer="restrict"),
    "no-level-0": Measurement(level0=False),
    "h1": Measurement(u_norm="h1"),
    "h1-semi": Measurement(u_norm="h1_semi"),
    "eps-voigt": Measurement(u_norm="eps_voigt"),
    "eps-engineering": Measurement(u_norm="eps_engineering"),
    "zeta-h1": Measurement(zeta_norm="h1"),
    "hold": Measurement(sampling="hold"),
    "hold-next": Measurement(sampling="hold_next"),
    "interpolate": Measurement(sampling="interpolate"),
    "max-each-part": Measurement(combine="sum_max"),
    "u0-interpolant": Measurement(initial="interpolant"),
    "left-diagonal": Measurement(diagonal="left"),
    "restrict+no-level-0": Measurement(transfer="restrict", level0=False),
    "restrict+hold": Measurement(transfer="restrict", sampling="hold"),
    "restrict+hold-next": Measurement(transfer="restrict", sampling="hold_next"),
    "restrict+h1": Measurement(transfer="restrict", u_norm="h1"),
    "restrict+u0-interpolant": Measurement(transfer="restrict", initial="interpolant"),
    "restrict+u0-interpolant+h1": Measurement(transfer="restrict", initial="interpolant", u_norm="h1"),
    "u0-interpolant+no-level-0": Measurement(initial="interpolant", level0=False),
    "left-diagonal+restrict": Measurement(diagonal="left", transfer="restrict"),
    "left-diagonal+u0-interpolant": Measurement(diagonal="left", initial="interpolant"),
}


def all_measurements(run_keys: Iterable[tuple[str, str]]) -> list[Measurement]:
    """Every combination of the measurement choices, for each (initial, diagonal) run key."""
    out = []
    for initial, diagonal in run_keys:
        for t, l0, un, zn, s, c in itertools.product(TRANSFERS, (True, False), U_NORMS, ZETA_NORMS, SAMPLINGS, COMBINES):
            out.append(Measurement(t, l0, un, zn, s, c, initial, diagonal))
    return out


# ----------------------------------------------------------------------------
# Norm matrices and the two transfer spaces
# ----------------------------------------------------------------------------


def fine_forms(ref: Reference) -> list[sp.csr_matrix]:
    """The six matrices of :data:`FORMS` on the reference's grid (eps and the zeta mass are the reference's own)."""
    import dolfinx.fem.petsc  # noqa: F401
    import ufl
    from dolfinx import fem

    V = ref.model.u.function_space
    du, w = ufl.TrialFunction(V), ufl.TestFunction(V)
    Z = fem.FunctionSpace(ref.model.geo.mesh, ("CG", 1))
    z, xi = ufl.TrialFunction(Z), ufl.TestFunction(Z)

    def shear(v):
        return 0.5 * (v[0].dx(1) + v[1].dx(0))

    def grid(a, perm):
        A = fem.petsc.assemble_matrix(fem.form(a))
        A.assemble()
        return petsc_to_scipy(A)[perm][:, perm].tocsr()

    return [ref.strain_gram, grid(shear(du) * shear(w) * ufl.dx, ref.pu), grid(ufl.inner(ufl.grad(du), ufl.grad(w)) * ufl.dx, ref.pu),
            grid(ufl.inner(du, w) * ufl.dx, ref.pu), ref.mass_zeta, grid(ufl.inner(ufl.grad(z), ufl.grad(xi)) * ufl.dx, ref.pz)]


def injection(nc: int, nf: int) -> np.ndarray:
    """Fine grid index of each coarse grid node (nested meshes): nodal interpolation onto the coarse mesh."""
    r = nf // nc
    row, col = np.divmod(np.arange((nc + 1) ** 2), nc + 1)
    return (r * row) * (nf + 1) + r * col


class Space:
    """Where a difference is measured: the fine grid (``prolong``) or the coarse grid (``restrict``).

    ``Q`` are the :data:`FORMS` matrices there (on the coarse grid P^T Q P: the coarse-mesh
    matrices, exactly, since the meshes nest); ``ref(i)`` the reference at stored level i
    there; ``coarse(u, zeta)`` a coarse solution there (vectors: u interleaved by node).
    """

    def __init__(self, transfer: str, data, Q: list[sp.csr_matrix], P: sp.csr_matrix, inj: np.ndarray) -> None:
        self.transfer, self.data, self.P, self.inj = transfer, data, P, inj
        if transfer == "prolong":
            self.Q = Q
        else:
            Pv = sp.kron(P, sp.identity(2), format="csr")
            self.Q = [(Pv.T @ q @ Pv).tocsr() if i < U_FORMS else (P.T @ q @ P).tocsr() for i, q in enumerate(Q)]
        self._Qa: np.ndarray | None = None

    def ref_block(self, i0: int, i1: int) -> tuple[np.ndarray, np.ndarray]:
        """The reference at stored levels i0..i1-1: (levels x u values, levels x zeta values)."""
        block = np.asarray(self.data[i0:i1] if self.transfer == "prolong" else self.data[i0:i1, self.inj])
        return block[:, :, :2].reshape(i1 - i0, -1), np.ascontiguousarray(block[:, :, 2])

    def coarse(self, u: np.ndarray, z: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        if self.transfer == "prolong":
            return (self.P @ u).ravel(), self.P @ z
        return u.ravel(), z

    def apply(self, u: np.ndarray, z: np.ndarray) -> list[np.ndarray]:
        """Q_f times (u, zeta) for every form."""
        return [q @ (u if i < U_FORMS else z) for i, q in enumerate(self.Q)]

    def forms(self, u: np.ndarray, z: np.ndarray) -> np.ndarray:
        """The six squared seminorms of (u, zeta)."""
        return np.array([(u if i < U_FORMS else z) @ qv for i, qv in enumerate(self.apply(u, z))])

    def ref_forms(self, block: int = 64) -> np.ndarray:
        """Q_f(reference) at every stored level (levels x 6), computed once."""
        if self._Qa is None:
            levels = self.data.shape[0]
            out = np.empty((levels, len(FORMS)))
            for i0 in range(0, levels, block):
                i1 = min(levels, i0 + block)
                U, Z = self.ref_block(i0, i1)
                for f, q in enumerate(self.Q):
                    X = U if f < U_FORMS else Z
                    out[i0:i1, f] = np.einsum("ij,ji->i", X, q @ X.T)
            self._Qa = out
        return self._Qa


# ----------------------------------------------------------------------------
# One coarse run, measured every way
# ----------------------------------------------------------------------------


class Series:
    """The squared seminorms of (reference - coarse) at each sample, per (transfer, sampling)."""

    def __init__(self) -> None:
        self.t: dict[tuple[str, str], list[float]] = {}
        self.f: dict[tuple[str, str], list[np.ndarray]] = {}

    def add(self, transfer: str, sampling: str, t, forms) -> None:
        key = (transfer, sampling)
        self.t.setdefault(key, []).extend(np.atleast_1d(t).tolist())
        self.f.setdefault(key, []).extend(np.atleast_2d(forms))

    def arrays(self, transfer: str, sampling: str) -> tuple[np.ndarray, np.ndarray]:
        return np.array(self.t[transfer, sampling]), np.array(self.f[transfer, sampling])


def evaluate(series: Series, m: Measurement, k: float) -> dict:
    """The error of one measurement from a run's series: error, its u and zeta parts, and where it is reached."""
    t, F = series.arrays(m.transfer, m.sampling)
    keep = np.ones(len(t), bool) if m.level0 else t >= k * (1 - 1e-9)
    t, F = t[keep], F[keep]
    eu = np.sqrt(np.maximum(F[:, :U_FORMS] @ np.array(U_WEIGHTS[m.u_norm], float), 0.0))
    ez = np.sqrt(np.maximum(F[:, U_FORMS:] @ np.array(Z_WEIGHTS[m.zeta_norm], float), 0.0))
    if m.combine == "max_sum":
        total = eu + ez
        i = int(np.argmax(total))
        return {"error": float(total[i]), "error_u": float(eu[i]), "error_zeta": float(ez[i]), "t_max": float(t[i])}
    i = int(np.argmax(eu))
    return {"error": float(eu.max() + ez.max()), "error_u": float(eu[i]), "error_zeta": float(ez.max()),
            "t_max": float(t[i])}


class Measurer:
    """One reference (one diagonal) and the spaces to measure coarse runs against it."""

    def __init__(self, ref: Reference, samplings: Iterable[str] = SAMPLINGS, transfers: Iterable[str] = TRANSFERS) -> None:
        self.ref = ref
        self.Q = fine_forms(ref)
        self.samplings, self.transfers = tuple(samplings), tuple(transfers)
        self.steps = np.rint(ref.times / ref.k).astype(np.int64)  # reference step of each stored level
        self._spaces: dict[tuple[str, int], Space] = {}
        self._P: dict[int, sp.csr_matrix] = {}

    def space(self, transfer: str, n: int) -> Space:
        key = (transfer, n if transfer == "restrict" else 0)
        if key not in self._spaces:
            P = self.P(n)
            self._spaces[key] = Space(transfer, self.ref.data, self.Q, P, injection(n, self.ref.n))
        sp_ = self._spaces[key]
        if transfer == "prolong":
            sp_.P = self.P(n)  # one fine space for every n; only the transfer changes
        return sp_

    def P(self, n: int) -> sp.csr_matrix:
        if n not in self._P:
            self._P[n] = prolongation(n, self.ref.n, self.ref.diagonal)
        return self._P[n]

    def run(self, n: int, k: float, initial: str = "elastic") -> tuple[Series, float]:
        """Run (n, k) and measure it every way; returns the series and the run's seconds."""
        from mpi4py import MPI

        from solver.config import load
        from solver.io.results import run
        from solver.run.model import build_model
        from solver.run.stepper import Stepper

        ref = self.ref
        cfg = load(ref.cfg_path, [*ref.overrides, f"mesh.nx={n}", f"mesh.ny={n}", f"time.k={k}", "output.xdmf=false"])
        m = round(k / ref.k)
        if abs(k / ref.k - m) > 1e-9:
            raise UsageError(f"k = {k} is not a multiple of the reference k = {ref.k}")
        t0 = time.perf_counter()
        model = build_model(cfg, MPI.COMM_SELF)
        flds = Fields(model, n)
        spaces = [self.space(tr, n) for tr in self.transfers]
        series = Series()
        prev: list[tuple | None] = [None] * len(spaces)

        def on_level(row: dict) -> None:
            j = round(row["t"] / k)
            i = ref.slot[j * m]
            u, z = flds.u(), flds.zeta()
            for s, space in enumerate(spaces):
                bu, bz = space.coarse(u, z)
                au, az = space.ref_block(i, i + 1)
                series.add(space.transfer, "coarse", row["t"], space.forms(au[0] - bu, az[0] - bz))
                if not {"hold", "hold_next", "interpolate"} & set(self.samplings):
                    continue
                Qb = space.apply(bu, bz)
                bb = np.array([(bu if f < U_FORMS else bz) @ Qb[f] for f in range(len(FORMS))])
                if prev[s] is not None:
                    self._between(series, space, prev[s], (bu, bz, Qb, bb), j, m)
                prev[s] = (bu, bz, Qb, bb)
                if j == cfg.time.steps:  # the last level: held and interpolated equal the coarse value there
                    direct = series.f[space.transfer, "coarse"][-1]
                    for sampling in ("hold", "hold_next", "interpolate"):
                        series.add(space.transfer, sampling, row["t"], direct)

        if initial == "elastic":
            run(model, on_step=on_level)
        else:  # u_0 = Pi^h u(0): the reference's level 0 at the coarse nodes, no elastic solve
            u0 = np.asarray(ref.data[0, injection(n, ref.n), :2])
            model.u.x.array.reshape(-1, 2)[:] = u0[flds.u_order]
            model.u.x.scatter_forward()
            on_level({"t": 0.0, "step": 0})
            stepper = Stepper(model)
            for step in range(1, cfg.time.steps + 1):
                on_level(stepper.step(step))
        return series, time.perf_counter() - t0

    def _between(self, series: Series, space: Space, prev: tuple, cur: tuple, j: int, m: int) -> None:
        """Samples at the stored reference levels in [t_{j-1}, t_j): held at level j-1 (or j after t_{j-1}),
        or linear in time."""
        lo, hi = np.searchsorted(self.steps, [(j - 1) * m, j * m])
        if hi <= lo:
            return
        t = self.ref.times[lo:hi]
        theta = (self.steps[lo:hi] - (j - 1) * m) / m
        U, Z = space.ref_block(lo, hi)
        Qa = space.ref_forms()[lo:hi]
        bu0, bz0, Qb0, bb0 = prev
        bu1, bz1, Qb1, bb1 = cur
        cross0 = np.column_stack([(U if f < U_FORMS else Z) @ Qb0[f] for f in range(len(FORMS))])
        cross1 = np.column_stack([(U if f < U_FORMS else Z) @ Qb1[f] for f in range(len(FORMS))])
        b01 = np.array([(bu0 if f < U_FORMS else bz0) @ Qb1[f] for f in range(len(FORMS))])
        if "hold" in self.samplings:
            series.add(space.transfer, "hold", t, Qa - 2 * cross0 + bb0)
        if "hold_next" in self.samplings:  # the interpolation formula with theta rounded up to 0 or 1
            th = (theta > 0).astype(float)[:, None]
            series.add(space.transfer, "hold_next", t,
                       Qa - 2 * ((1 - th) * cross0 + th * cross1) + (1 - th) * bb0 + th * bb1)
        if "interpolate" in self.samplings:
            th = theta[:, None]
            series.add(space.transfer, "interpolate", t,
                       Qa - 2 * ((1 - th) * cross0 + th * cross1) + (1 - th) ** 2 * bb0 + 2 * th * (1 - th) * b01
                       + th ** 2 * bb1)


# ----------------------------------------------------------------------------
# The study and its report
# ----------------------------------------------------------------------------


def study(cfg_path: Path, named: dict[str, Measurement], ns, ks, n_ref: int, k_ref: float, cache: Path,
          search: bool = True, log: Callable[[str], None] = print) -> dict:
    """Every measurement (the named ones, and with ``search`` every combination) on the (n, k) grid.

    Returns {"named": {name: rows}, "search": {label: rows}, "references": [...], "seconds": ...}; a row
    holds n, k, error, error_u, error_zeta, t_max, paper_error and ratio.
    """
    t0 = time.perf_counter()
    run_keys = sorted({m.run_key for m in named.values()})
    combos = all_measurements(run_keys) if search else []
    measurers: dict[str, Measurer] = {}
    for diagonal in sorted({d for _, d in run_keys}):
        ref = Reference(cfg_path, n_ref, k_ref, ks, cache, [f"mesh.diagonal='{diagonal}'"])
        info = ref.info
        log(f"reference ({diagonal} diagonal) n={n_ref} k={k_ref}: {info['levels']} stored levels"
            + (" (from cache)" if info["cached"] else f" ({info['seconds']:.1f} s)"))
        measurers[diagonal] = Measurer(ref)
    named_rows: dict[str, list[dict]] = {name: [] for name in named}
    search_rows: dict[str, list[dict]] = {m.label(): [] for m in combos}
    for initial, diagonal in run_keys:
        ms = measurers[diagonal]
        for n in ns:
            for k in ks:
                series, seconds = ms.run(n, k, initial)
                pe = paper_error(n, k)
                for name, m in named.items():
                    if m.run_key == (initial, diagonal):
                        named_rows[name].append(_row(series, m, n, k, pe))
                for m in combos:
                    if m.run_key == (initial, diagonal):
                        search_rows[m.label()].append(_row(series, m, n, k, pe))
                log(f"u0 {initial}, {diagonal} diagonal, n={n:4d} k={k:<6g}: run + measurement {seconds:.1f} s")
    refs = [{"diagonal": d, "n": ms.ref.n, "k": ms.ref.k, "stored_levels": int(ms.ref.info["levels"])}
            for d, ms in measurers.items()]
    return {"named": named_rows, "search": search_rows, "references": refs, "seconds": time.perf_counter() - t0,
            "measurements": {name: asdict(m) for name, m in named.items()}}


def _row(series: Series, m: Measurement, n: int, k: float, pe: float | None) -> dict:
    rec = evaluate(series, m, k)
    return {"n": n, "k": k, **rec, "paper_error": pe, "ratio": rec["error"] / pe if pe else None}


def summary(rows: list[dict]) -> dict:
    """Ratios to the paper: max, median, min, the largest factor off (max |log ratio|), how many within 20 %,
    and the observed slopes (in h + k over all points, as for Table 1; in k at the finest n)."""
    ratios = np.array([r["ratio"] for r in rows if r["ratio"] is not None])
    rt = rates(rows)
    n_max = str(max(r["n"] for r in rows))
    paper_k = [(r["k"], r["paper_error"]) for r in rows if r["n"] == int(n_max) and r["paper_error"]]
    out = {"max_ratio": float(ratios.max()), "median_ratio": float(np.median(ratios)), "min_ratio": float(ratios.min()),
           "max_factor": float(np.exp(np.abs(np.log(ratios)).max())),
           "within_20pct": int(np.sum(np.abs(ratios - 1) <= 0.2)), "entries": int(len(ratios)),
           "slope_h_plus_k": rt["h_plus_k"], "paper_slope_h_plus_k": rt.get("paper_h_plus_k"),
           "slope_k_finest": rt["k"][n_max], "finest_n": int(n_max)}
    if len(paper_k) > 1:
        out["paper_slope_k_finest"] = float(np.polyfit(*np.log(np.array(paper_k)).T, 1)[0])
    return out


def _ratio_table(rows: list[dict]) -> list[str]:
    ks = sorted({r["k"] for r in rows}, reverse=True)
    ns = sorted({r["n"] for r in rows})
    by = {(r["n"], r["k"]): r for r in rows}
    md = ["| n \\ k | " + " | ".join(f"{k:g}" for k in ks) + " |", "|---|" + "---|" * len(ks)]
    for n in ns:
        md.append(f"| {n} | " + " | ".join(
            f"{by[n, k]['ratio']:.2f}" if (n, k) in by and by[n, k]["ratio"] is not None else "" for k in ks) + " |")
    return md


def _summary_line(name: str, s: dict) -> str:
    return (f"| {name} | {s['max_ratio']:.2f} | {s['median_ratio']:.2f} | {s['min_ratio']:.2f} | {s['max_factor']:.2f} "
            f"| {s['within_20pct']}/{s['entries']} | {s['slope_h_plus_k']:.2f} | {s['slope_k_finest']:.2f} |")


def write(result: dict, out: Path, command: str, top: int = 10) -> dict:
    """table1_variants.md (summaries, every named variant's 36 ratios, the best combinations), .json, .csv."""
    out.mkdir(parents=True, exist_ok=True)
    named = {name: summary(rows) for name, rows in result["named"].items()}
    search = {label: summary(rows) for label, rows in result["search"].items()}
    ranked = sorted(search, key=lambda lab: search[lab]["max_factor"])
    best_named = min(named, key=lambda nm: named[nm]["max_factor"])
    any_row = next(iter(result["named"].values()))
    s0 = named[best_named]
    header = ["| variant | max ratio | median ratio | min ratio | max factor off | within 20 % | slope in h + k "
              f"| slope in k at n = {s0['finest_n']} |", "|---|---|---|---|---|---|---|---|"]
    paper_line = (f"Paper: slope in h + k {s0['paper_slope_h_plus_k']:.2f}, in k at n = {s0['finest_n']} "
                  f"{s0.get('paper_slope_k_finest', float('nan')):.2f}.")
    refs = ", ".join(f"{r['diagonal']} diagonal n = {r['n']}, k = {r['k']} ({r['stored_levels']} stored levels)"
                     for r in result["references"])
    md = ["# Table 1: which measurement reproduces the paper's numbers (issue 17)", "",
          f"Produced by `{command}` in {result['seconds']:.0f} s. References: {refs}. "
          f"{len(any_row)} (n, k) entries per variant; each ratio is ours / paper.", "",
          "What the choices mean (`studies/table1_variants.py`): *transfer* prolong = the coarse solution on the fine "
          "mesh (ours), restrict = the reference interpolated at the coarse nodes and the error measured on the coarse "
          "mesh; *level 0* whether t = 0 is in the maximum; *u norm* eps = ||eps(.)||_L2 (the paper's V norm), "
          "eps_voigt = shear strain counted once, eps_engineering = gamma_12 = 2 eps_12, h1_semi = ||grad .||, "
          "h1 = full H1; *zeta norm* l2 or h1; *sampling* coarse levels only, or every stored reference level "
          "(every 2nd reference step here, t a multiple of 0.001) with the coarse solution held (hold: the last "
          "level; hold_next: the next one) or linear in time; *combine* max_n(u part + zeta part) (the paper's "
          "formula) or max u part + max zeta part; "
          "*u0* elastic = the discrete elastic contact solve (Remark 7), interpolant = Pi^h of the reference's u at "
          "t = 0 (Corollary 9); *diagonal* of the reference and the coarse meshes.", "",
          "## Named variants", "", paper_line, "", *header]
    md += [_summary_line(name, named[name]) for name in named]
    close = [nm for nm in named if named[nm]["within_20pct"] == named[nm]["entries"]]
    close_s = [lab for lab in search if search[lab]["within_20pct"] == search[lab]["entries"]]
    md += ["", f"Closest named variant (smallest largest factor off): **{best_named}**, max ratio "
           f"{s0['max_ratio']:.2f}, median {s0['median_ratio']:.2f}, min {s0['min_ratio']:.2f}; "
           f"{s0['within_20pct']}/{s0['entries']} entries within 20 %."]
    if search:
        b = search[ranked[0]]
        md += [f"Closest of all {len(search)} combinations: **{ranked[0]}**, max ratio {b['max_ratio']:.2f}, "
               f"median {b['median_ratio']:.2f}, min {b['min_ratio']:.2f}; {b['within_20pct']}/{b['entries']} "
               "within 20 %."]
    md += ["", ("Variants within 20 % at every entry: " + ", ".join(close + close_s)) if close or close_s
           else "**No variant comes within 20 % of the paper at every entry.**", ""]
    for name, rows in result["named"].items():
        s = named[name]
        m = result["measurements"][name]
        md += [f"### {name}", "", "Choices: " + ", ".join(f"{key} = {val}" for key, val in m.items()) + ".", "",
               *_ratio_table(rows), "",
               f"max {s['max_ratio']:.2f}, median {s['median_ratio']:.2f}, slope in h + k {s['slope_h_plus_k']:.2f}, "
               f"in k at n = {s['finest_n']} {s['slope_k_finest']:.2f}.", ""]
    if search:
        md += [f"## Every combination of the measurement choices ({len(search)})", "",
               "Each combination of transfer x level 0 x u norm x zeta norm x sampling x combine, for each run "
               f"(u0 and diagonal) above. The {top} closest by the largest factor off:", "", *header]
        md += [_summary_line(lab, search[lab]) for lab in ranked[:top]]
        md += ["", "Their 36 ratios are in `table1_variants.csv`; the summaries of all combinations in "
               "`table1_variants.json`.", ""]
        for lab in ranked[:3]:
            md += [f"### {lab}", "", *_ratio_table(result["search"][lab]), ""]
    (out / "table1_variants.md").write_text("\n".join(md))
    with open(out / "table1_variants.csv", "w", newline="") as fh:
        cols = ["variant", "n", "k", "error", "error_u", "error_zeta", "t_max", "paper_error", "ratio"]
        wr = csv.DictWriter(fh, fieldnames=cols, extrasaction="ignore")
        wr.writeheader()
        for name, rows in [*result["named"].items(), *((lab, result["search"][lab]) for lab in ranked[:top])]:
            for r in rows:
                wr.writerow({**r, "variant": name})
    doc = {"command": command, "references": result["references"], "seconds": result["seconds"],
           "named": {name: {"measurement": result["measurements"][name], "summary": named[name]} for name in named},
           "search": {lab: search[lab] for lab in ranked}}
    (out / "table1_variants.json").write_text(json.dumps(doc, indent=1))
    return {"named": named, "search": search, "ranked": ranked, "best_named": best_named}


def main(args) -> int:
    """``study table1-variants``: one process; unknown variant names were refused by the parser."""
    from mpi4py import MPI

    if MPI.COMM_WORLD.size > 1:
        if MPI.COMM_WORLD.rank == 0:
            print("error: study table1-variants runs in one process (the reference and its transfers are serial)",
                  file=sys.stderr)
        return 2
    named = {name: VARIANTS[name] for name in args.variants}
    ns, ks = args.ns or list(PAPER_NS), args.ks or list(PAPER_KS)
    bad = [f"n = {n} does not divide --ref-n {args.ref_n}" for n in ns if n <= 0 or args.ref_n % n] + [
        f"k = {k:g} is not a multiple of --ref-k {args.ref_k:g}" for k in ks
        if k <= 0 or abs(k / args.ref_k - round(k / args.ref_k)) > 1e-9]
    if bad:
        print(f"error: {bad[0]} (the meshes must nest and the time levels coincide)", file=sys.stderr)
        return 2
    result = study(Path(args.config), named, ns, ks, args.ref_n, args.ref_k, Path(args.cache), search=not args.no_search,
                   log=lambda s: print(s, flush=True))
    command = "python -m studies study " + " ".join(args.argv)
    summ = write(result, Path(args.output), command)
    print(f"wrote {args.output}/table1_variants.md, .csv, .json; closest named variant: {summ['best_named']}")
    return 0
