"""The damage's space part: zeta's error on a mesh from its differences on nested meshes at one step
(docs/guide/accuracy.md, "damage").

The runs share the step, so the time error cancels in their differences. With e ~ cells^-s, s is observed from
two differences within [ZETA_EXPONENT_MIN, ZETA_EXPONENT_MAX[q]] (a rate of 1 in h up to the best rate of zeta's
degree q in L2; these are the 2-D exponents, cells ~ h^-2: in 3-D, cells ~ h^-3, the same rates in h are 2/3 of
them), and e = D / (ratio^s - 1); with one earlier mesh s is the rate 1 in h (1/2 in 2-D, 1/3 in 3-D), with none
the difference to the uniform refinement (h halved: 4 children per triangle, 8 per tetrahedron) gives e = 2 D.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
import ufl
from dolfinx import fem
from mpi4py import MPI

from solver.config import Config
from solver.errors import SolveFailure
from solver.mesh.adapt import refine_uniformly
from solver.mesh.geometry import Geometry
from solver.mesh.transfer import interpolation_matrix

from .scene import step, with_changes
from .solves import HALVINGS, PilotRun, pilot_run

# zeta's error e ~ cells^-s on nested 2-D meshes (cells ~ h^-2): s at least 1/2 (a rate of 1 in h) and at most the
# degree's best rate in L2 ((q + 1) in h: s = (q + 1) / 2); in dimension d the same rates in h are s * 2 / d
ZETA_EXPONENT_MIN = 0.5
ZETA_EXPONENT_MAX = {1: 1.0, 2: 1.5}


class ZetaRuns:
    """Runs of a scene with damage at one step on nested meshes, each made once per (mesh, step). A run's level 0
    starts from the t = 0 solution :meth:`start_from` was given for its mesh and degree, where there is one."""

    def __init__(self) -> None:
        self._made: dict[tuple[int, float], PilotRun] = {}
        self._starts: dict[tuple[int, int], tuple[Geometry, np.ndarray]] = {}

    def start_from(self, geo: Geometry, degree: int, u0: np.ndarray) -> None:
        """The t = 0 problem's solution on ``geo`` at u's ``degree``: a run there starts from it."""
        self._starts[id(geo), degree] = (geo, u0)

    def _start(self, geo: Geometry, degree: int) -> np.ndarray | None:
        kept = self._starts.get((id(geo), degree))
        return kept[1] if kept is not None and kept[0] is geo else None

    def on(self, cfg: Config, comm: MPI.Comm, geos: Sequence[Geometry]) -> list[PilotRun]:
        """Runs of ``cfg`` on ``geos`` at its step; if Newton fails on one, all at half the step (up to HALVINGS
        times)."""
        for halving in range(HALVINGS + 1):
            k = cfg.time.k / 2**halving
            at_step = with_changes(cfg, step(k))
            try:
                for geo in geos:
                    if (id(geo), k) not in self._made:
                        start = self._start(geo, cfg.discretization.u_degree)
                        self._made[id(geo), k] = pilot_run(at_step, comm, geo, start=start)
                return [self._made[id(geo), k] for geo in geos]
            except SolveFailure:
                if halving == HALVINGS:
                    raise
        raise AssertionError("unreachable: the last halving re-raises")


def zeta_difference(coarse: PilotRun, fine: PilotRun, comm: MPI.Comm) -> float:
    """max over levels of ||zeta_coarse - zeta_fine||, the coarse zeta interpolated on the fine (nested) mesh."""
    Zf = fine.model.damage.V
    owned = Zf.dofmap.index_map.size_local
    dim = Zf.mesh.topology.dim  # the points lie in the mesh's dimension
    P = interpolation_matrix(coarse.model.damage.V, Zf.tabulate_dof_coordinates()[:owned, :dim])
    d = fem.Function(Zf)
    form = fem.form(d * d * ufl.dx)
    largest = 0.0
    for zc, zf in zip(coarse.zeta, fine.zeta):
        d.x.array[:owned] = zf[:owned] - P @ zc
        d.x.scatter_forward()
        largest = max(largest, math.sqrt(max(comm.allreduce(fem.assemble_scalar(form), op=MPI.SUM), 0.0)))
    return largest


def exponent_range(zeta_degree: int, dim: int = 2) -> tuple[float, float]:
    """The exponents s of e ~ cells^-s that zeta's error may have on nested meshes of dimension ``dim``: a rate of 1
    in h up to its degree's best rate in L2."""
    return ZETA_EXPONENT_MIN * 2.0 / dim, ZETA_EXPONENT_MAX[zeta_degree] * 2.0 / dim


def observed_exponent(cells: tuple[int, int, int], d_ab: float, d_bc: float, zeta_degree: int = 1,
                      dim: int = 2) -> float:
    """The exponent s of e(N) = A N^-s (N cells) from the differences of three nested meshes a, b, c:
    d_ab / d_bc = (N_a^-s - N_b^-s) / (N_b^-s - N_c^-s), solved for s within :func:`exponent_range` of the degree
    and dimension (a ratio outside what that range gives is clamped to its end)."""
    na, nb, nc = (float(n) for n in cells)

    def model(s: float) -> float:
        return (na**-s - nb**-s) / (nb**-s - nc**-s)

    lo, hi = exponent_range(zeta_degree, dim)
    ratio = d_ab / d_bc if d_bc > 0 else math.inf
    if not ratio > model(lo):  # also NaN
        return lo
    if ratio >= model(hi):
        return hi
    for _ in range(60):  # model(s) increases with s
        mid = 0.5 * (lo + hi)
        lo, hi = (mid, hi) if model(mid) < ratio else (lo, mid)
    return 0.5 * (lo + hi)


@dataclass(frozen=True)
class ZetaSpace:
    """zeta's space error bound on a mesh, and the uniform refinement it was measured against (or None)."""

    bound: float
    finer: Geometry | None


def zeta_space(cfg: Config, comm: MPI.Comm, geo: Geometry, earlier: Sequence[Geometry] = (),
               runs: ZetaRuns | None = None) -> ZetaSpace:
    """Estimate of zeta's space error on ``geo``, from its differences to ``earlier`` meshes that ``geo`` refines
    (the coarsest first), with e(N) = A N^-s over the number of cells N:
    - two earlier meshes a, b: s observed from the two differences (:func:`observed_exponent`), and
      e = D_bc / ((N_c / N_b)^s - 1);
    - one: s = 1/2 in 2-D, 1/3 in 3-D (a rate of 1 in h: rho = (N_b / N_c)^s, e = D rho / (1 - rho));
    - none: from ``geo``'s uniform refinement, e = 2 D (h halved, rate 1 in h).
    ``runs``: the runs already made. The bound is 0 without damage (nothing is run)."""
    if not cfg.damage.enabled:
        return ZetaSpace(0.0, None)
    finer = None if earlier else refine_uniformly(geo)
    meshes = [*earlier[-2:], geo] if earlier else [geo, finer]
    made = (ZetaRuns() if runs is None else runs).on(cfg, comm, meshes)
    cells = [m.num_cells() for m in meshes]
    if finer is not None:
        return ZetaSpace(2.0 * zeta_difference(made[0], made[1], comm), finer)
    d_bc = zeta_difference(made[-2], made[-1], comm)
    dim = geo.dim
    s = exponent_range(cfg.discretization.zeta_degree, dim)[0]
    if len(made) == 3:
        s = observed_exponent(tuple(cells), zeta_difference(made[0], made[1], comm), d_bc,
                              cfg.discretization.zeta_degree, dim)
    return ZetaSpace(d_bc / ((cells[-1] / cells[-2]) ** s - 1.0), None)
