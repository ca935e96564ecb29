"""Accuracy on demand: the degree, the mesh and the step that bring the paper's error below a tolerance.

The error is the paper's norm, max over levels of ||eps(u - u_exact)|| + ||zeta - zeta_exact||_L2
(docs/model.md §3.6). It is bounded by a space part and a time part (``accuracy.space_share``,
default one half, bounds the time part's share by 1 - space_share):

- **space, displacement** -- the residual estimator (solver/physics/estimator.py) times a constant C
  measured against known errors (``study estimator``: C = error/eta is 3.0-3.9e-3 for P1 and
  1.55-1.74e-3 for P2 on Example 1, E = 100, nu = 0.3, uniform and adapted meshes). C scales
  as 1/(2 mu) (eta is a stress, the error a strain), so C = c_p / (2 mu) with the largest
  measured values rounded up.
  The t = 0 problem is solved on meshes refined by Dörfler marking until C eta_0 times the
  growth of eta over the run (measured on the start mesh) is within its share;
- **space, damage** -- the differences of zeta on the chosen mesh and on up to two earlier,
  nested meshes of its sequence, at the same step (the time error cancels): with e ~ cells^-s,
  s observed from the two differences within [1/2, 1] (a rate of 1 to 2 in h), e = D / (ratio^s - 1);
  with one earlier mesh s = 1/2, with none the difference to the uniform refinement (e = 2 D);
- **time** -- step doubling on the start mesh with the lowest degree (the time error hardly
  depends on the degree): runs at k0, k0/2 and k0/4 (k0 = T/10) give the observed order p
  (at most the scheme's) and the error of k0/4, D/(2^p - 1); the step is the largest
  T/(10 2^j) whose extrapolated error is within (1 - space_share) TOL (times 0.8).

The step is chosen first; the space parts then get what its time error leaves of TOL
(the admissible steps halve, so the time part is often far below its share).

The degree is chosen by predicted cost: the t = 0 problem is solved once per degree on the
start mesh, the measured rates of adapted meshes (error ~ dofs^-0.49 for P1, dofs^-1.02 for
P2, ``study estimator``) extrapolate the dofs each needs, and the cost per dof and step is
measured (P2 is 1.13x P1 at equal dofs, benchmarks/results/bench.md). The t = 0 solves use the
scene without memory and damage (level 0 is the elastic contact problem, which neither
touches), which is cheaper to build. The damage's degree follows the displacement's
(P2 u: P2 zeta): zeta's source is a function of eps(u), of degree 2 (p - 1) in a cell, and
where zeta has a front (clipped at zeta*, configs/hard.toml) P1 zeta converged only like h,
so that the damage's part forced uniform refinements (planning ~90 s at TOL 1e-2); P2 zeta's
differences there fall about like h^1.5-1.9 (1.27e-2, 3.38e-3, 1.18e-3 on 128 ... 8,192 cells at
k = T/10), it plans TOL 1e-2 in about 3 s, and it costs little per step (the memory rule of P2/P2, degree 4, has
the 6 points of P2/P1's degree 3). On Example 1's 938-cell plan for 1e-3 the damage's
estimate falls from 2.7e-4 (P1 zeta) to 4.6e-5. The order in time is 2 where the scene
allows it (the same cost per step, far fewer steps), else 1. The mesh is then fixed for the
run: no history moves between meshes.
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass, field

import numpy as np
import ufl
from dolfinx import fem
from mpi4py import MPI

from solver.config import from_dict, merge, to_dict
from solver.errors import ConfigError, SolveFailure, ToleranceError
from solver.mesh.adapt import refine, refine_uniformly
from solver.mesh.geometry import build
from solver.mesh.transfer import interpolation_matrix
from solver.physics.estimator import dorfler, estimator_for
from solver.run.model import build_model
from solver.run.stepper import Stepper, levels

# C times 2 mu (mu the shear modulus E / (2 (1 + nu))): C measured on Example 1 (E = 100, nu = 0.3), rounded up
C_TIMES_2MU = {1: 4.0e-3 * 100.0 / 1.3, 2: 1.8e-3 * 100.0 / 1.3}
COST_PER_DOF = {1: 1.0, 2: 1.13}  # bench.md: P1 n=128 9.70 ms, P2 n=64 10.94 ms per step, both 33,282 dofs
N0 = 10  # the coarsest step is T / N0; every step considered is T / (N0 2^j)
SAFETY = 0.8
ADAPTED_RATE = {1: 0.49, 2: 1.02}  # error ~ dofs^-rate on Dörfler-adapted meshes (estimator.md, Example 1)
GROWTH_AT_0 = 1.5  # eta growing more over the run: adapt to its largest level instead of t = 0
THETA_MAX = 0.95  # the largest Dörfler fraction (far from the target)
ZETA_SHARE = 0.3  # of the space share, left to the damage's space error while the mesh is adapted
# zeta's part over ZETA_SHARE but at most ROOM_ZETA_MAX of the space share: u's mesh is adapted on to make room
# (ROOM_MARGIN of zeta's part kept for its change on the new mesh) before any uniform refinement
ROOM_ZETA_MAX = 0.6
ROOM_MARGIN = 0.25
# zeta's error e ~ cells^-s on nested meshes: s observed, at least 1/2 (a rate of 1 in h) and at most the degree's
# best rate in L2 ((q + 1) in h: s = (q + 1) / 2)
ZETA_EXPONENT_MIN = 0.5
ZETA_EXPONENT_MAX = {1: 1.0, 2: 1.5}
# memory a run needs per displacement dof (all ranks together): 8.7 GB at 1,042,802 dofs, measured on a
# tolerance run of Example 1 (issue 32); the planner never grows a mesh past MEMORY_SHARE of the machine's memory
BYTES_PER_DOF = 8.4e3
MEMORY_SHARE = 0.8
CHOSEN_KEYS = ("mesh.nx", "mesh.ny", "mesh.nz", "time.k", "discretization.u_degree", "discretization.zeta_degree",
               "time.order")


@dataclass
class Plan:
    """What the tolerance chose, and the estimates behind it."""

    tolerance: float  # absolute
    degree: int
    order: int
    k: float
    geo: object  # Geometry of the chosen (adapted) mesh
    start: dict  # the start mesh's changes to the scene ({} or {"mesh": {"nx": .., "ny": ..}})
    estimate: dict[str, float]  # space_u, space_zeta, time: each a bound of its part
    C: float
    growth: float
    time_rate: float
    time_profile: tuple[np.ndarray, np.ndarray]  # (t, estimated time error at k) from the pilot runs
    adaptation: list[dict] = field(default_factory=list)
    seconds: float = 0.0
    scene: object = None  # the Config planned for

    @property
    def changes(self) -> dict:
        """The changes to the scene of the chosen degrees, order and step (the mesh is ``geo``)."""
        return _merged(self.start, degrees(self.degree), {"time": {"order": self.order, "k": self.k}})

    @property
    def config(self):
        """The scene planned for with the chosen degrees, order and step: what the run is built from."""
        return self.scene.replace(self.changes, label="plan")

    def time_error(self, t: float) -> float:
        ts, es = self.time_profile
        i = int(np.searchsorted(ts, t + 1e-12 * max(1.0, t), side="right")) - 1
        return float(es[max(i, 0)]) if len(es) else 0.0

    def summary(self) -> dict:
        return {"tolerance": self.tolerance, "u_degree": self.degree, "zeta_degree": self.degree, "order": self.order,
                "k": self.k,
                "cells": self.geo.num_cells(), "estimate": self.estimate, "C": self.C, "growth": self.growth,
                "time_rate": self.time_rate,
                "adaptation": [{k: v for k, v in r.items() if not k.startswith("_")} for r in self.adaptation],
                "planning_seconds": self.seconds}


def degrees(d: int) -> dict:
    """The changes of degree ``d`` for u and zeta alike: zeta's degree follows u's (module docstring)."""
    return {"discretization": {"u_degree": d, "zeta_degree": d}}


def _with(cfg, *changes: dict):
    """``cfg`` with ``changes`` (validated: :meth:`Config.replace`)."""
    return cfg.replace(_merged(*changes), label="accuracy plan")


def _merged(*changes: dict) -> dict:
    """One table of changes from several (the later win)."""
    out: dict = {}
    for c in changes:
        out = merge(out, c)
    return out


def _k(k: float) -> dict:
    return {"time": {"k": k}}


def contradicting(overrides: list[str]) -> list[str]:
    """The ``--set`` overrides a tolerance decides itself (mesh size, step, degrees, order)."""
    return [o for o in overrides if o.split("=", 1)[0].strip() in CHOSEN_KEYS]


def _start_mesh(cfg, comm: MPI.Comm) -> dict:
    """A coarse start for a built-in rectangle: about 4 cells across its shorter side (doubled until the boundary
    parts' ends fall on nodes); a gmsh mesh starts as it is. Returns the scene's changes."""

    if cfg.mesh.kind != "rectangle":
        return {}
    (x0, y0), (x1, y1) = cfg.mesh.corners
    h = min(x1 - x0, y1 - y0) / 4
    for scale in (1, 2, 4, 8, 16):
        nx, ny = max(1, round((x1 - x0) / h)) * scale, max(1, round((y1 - y0) / h)) * scale
        start = {"mesh": {"nx": nx, "ny": ny}}
        try:
            build(comm, _with(cfg, start).mesh, cfg.boundaries, cfg.dim)
            return start
        except ConfigError:
            continue
    return {}


def _order(cfg) -> int:
    """2 where the scene allows the second-order scheme, else 1."""
    try:
        _with(cfg, {"time": {"order": 2}})
        return 2
    except ConfigError:
        return 1


def _dofs(model) -> int:
    """Displacement dofs over all ranks."""
    dofmap = model.u.function_space.dofmap
    return dofmap.index_map.size_global * dofmap.index_map_bs


def _elastic(cfg):
    """The scene without memory and damage: its level 0 (the elastic contact problem) is the same."""

    data = to_dict(cfg)
    data["memory"] = {"kernel": "none"}
    data["damage"] = {"enabled": False}
    return from_dict(data, source=cfg.source)


class _Level0:
    """The t = 0 problem on a mesh: its solution, eta_K^2 and eta."""

    def __init__(self, cfg, comm: MPI.Comm, geo) -> None:

        cfg = _elastic(cfg)
        self.model = build_model(cfg, comm, geo)
        row = Stepper(self.model).step(0)
        self.strain_norm = row["strain_norm"]
        est = estimator_for(self.model)
        self.eta2 = est.cells()
        self.eta = est.total(self.eta2)
        self.dofs = _dofs(self.model)


class _Worst:
    """A coarse-step run on a mesh (to the scene's T as overridden): eta and eta_K^2 at its level of largest eta
    (scenes whose load starts at zero have nothing to adapt to at t = 0). A step Newton cannot take on a finer
    mesh is halved (up to 3 times)."""

    def __init__(self, cfg, comm: MPI.Comm, geo) -> None:

        for halving in range(4):
            self.model = model = build_model(_with(cfg, _k(cfg.time.k / 2**halving)), comm, geo)
            est = estimator_for(model)
            worst: list = [-1.0, None]

            def keep(row, est=est, worst=worst):
                eta2 = est.cells()
                eta = est.total(eta2)
                if eta > worst[0]:
                    worst[:] = [eta, eta2]

            try:
                for row in levels(model):
                    keep(row)
                break
            except SolveFailure:
                if halving == 3:
                    raise
        self.eta, self.eta2 = worst
        self.dofs = _dofs(model)


def _theta(theta: float, ratio: float) -> float:
    """The Dörfler fraction for an estimate ``ratio`` times its target: the cells carrying 1 - 1/ratio^2 of
    eta^2 (refining them all away would leave the target's eta^2), at least ``theta`` and at most THETA_MAX, so
    that few solve-estimate-refine rounds are needed (each is a mesh to build)."""
    return min(THETA_MAX, max(theta, 1.0 - 1.0 / ratio**2))


class _Pilot:
    """A run on a fixed mesh that keeps u and zeta at every level (and eta_n with ``estimate``)."""

    def __init__(self, cfg, comm, geo, estimate: bool = False) -> None:

        self.model = model = build_model(cfg, comm, geo)
        est = estimator_for(model) if estimate else None
        self.u, self.zeta, self.eta, self.t = [], [], [], []

        def keep(row):
            self.t.append(row["t"])
            self.u.append(model.u.x.array.copy())
            if model.damage is not None:
                self.zeta.append(model.damage.zeta.x.array.copy())
            if est is not None:
                self.eta.append(est.total())

        for row in levels(model):
            keep(row)


def _norms(model, comm: MPI.Comm):
    """||eps(v)|| and ||z|| of arrays on the model's spaces (collective)."""

    V = model.u.function_space
    dv = fem.Function(V)
    eps = ufl.sym(ufl.grad(dv))
    fu = fem.form(ufl.inner(eps, eps) * ufl.dx)
    fz = dz = None
    if model.damage is not None:
        dz = fem.Function(model.damage.V)
        fz = fem.form(dz * dz * ufl.dx)

    def norm_u(a: np.ndarray) -> float:
        dv.x.array[:] = a
        return math.sqrt(max(comm.allreduce(fem.assemble_scalar(fu), op=MPI.SUM), 0.0))

    def norm_z(a: np.ndarray) -> float:
        if fz is None:
            return 0.0
        dz.x.array[:] = a
        return math.sqrt(max(comm.allreduce(fem.assemble_scalar(fz), op=MPI.SUM), 0.0))

    return norm_u, norm_z


def _time_estimate(runs: list[_Pilot], order: int, comm) -> tuple[float, float, np.ndarray, np.ndarray]:
    """From runs at k, k/2, k/4 on one mesh: (observed order p, error of the k/4 run, times, error profile of the
    k/4 run at the k/2 levels)."""
    norm_u, norm_z = _norms(runs[0].model, comm)

    def diff(a: _Pilot, b: _Pilot) -> np.ndarray:
        out = []
        for j in range(len(a.t)):
            d = norm_u(a.u[j] - b.u[2 * j])
            if a.zeta:
                d += norm_z(a.zeta[j] - b.zeta[2 * j])
            out.append(d)
        return np.array(out)

    d1, d2 = diff(runs[0], runs[1]), diff(runs[1], runs[2])
    m1, m2 = float(d1.max()), float(d2.max())
    if m2 <= 1e-14 * max(1.0, m1):
        return float(order), 0.0, np.array(runs[1].t), np.zeros(len(d2))
    p = math.log2(m1 / m2) if m1 > 0 else float(order)
    p = min(max(p, 0.5), float(order))
    return p, m2 / (2**p - 1), np.array(runs[1].t), d2 / (2**p - 1)


def _zeta_runs(cfg, comm, geos, kept: dict) -> list[_Pilot]:
    """Runs at the same step on nested meshes (the time error cancels in their differences) of a scene with
    damage. If Newton fails on one, all are repeated with half the step. ``kept``: runs already made, by (mesh,
    step)."""
    for halving in range(4):
        step = cfg.time.k / 2**halving
        at_step = _with(cfg, _k(step))
        try:
            for geo in geos:
                if (id(geo), step) not in kept:
                    kept[id(geo), step] = _Pilot(at_step, comm, geo)
            return [kept[id(geo), step] for geo in geos]
        except SolveFailure:
            if halving == 3:
                raise
    raise AssertionError("unreachable: the last halving re-raises")


def _zeta_difference(coarse: _Pilot, fine: _Pilot, comm: MPI.Comm) -> float:
    """max over levels of ||zeta_coarse - zeta_fine||, the coarse zeta interpolated on the fine (nested) mesh."""


    Zf = fine.model.damage.V
    owned = Zf.dofmap.index_map.size_local
    P = interpolation_matrix(coarse.model.damage.V, Zf.tabulate_dof_coordinates()[:owned, :2])
    d = fem.Function(Zf)
    form = fem.form(d * d * ufl.dx)
    worst = 0.0
    for zc, zf in zip(coarse.zeta, fine.zeta):
        d.x.array[:owned] = zf[:owned] - P @ zc
        d.x.scatter_forward()
        worst = max(worst, math.sqrt(max(comm.allreduce(fem.assemble_scalar(form), op=MPI.SUM), 0.0)))
    return worst


def observed_exponent(cells: tuple[int, int, int], d_ab: float, d_bc: float, zeta_degree: int = 1) -> float:
    """The exponent s of e(N) = A N^-s (N cells) from the differences of three nested meshes a, b, c:
    d_ab / d_bc = (N_a^-s - N_b^-s) / (N_b^-s - N_c^-s), solved for s within [ZETA_EXPONENT_MIN,
    ZETA_EXPONENT_MAX[zeta_degree]] (a ratio outside what that range gives is clamped to its end)."""
    na, nb, nc = (float(n) for n in cells)

    def model(s: float) -> float:
        return (na**-s - nb**-s) / (nb**-s - nc**-s)

    lo, hi = ZETA_EXPONENT_MIN, ZETA_EXPONENT_MAX[zeta_degree]
    ratio = d_ab / d_bc if d_bc > 0 else math.inf
    if not ratio > model(lo):  # also NaN
        return lo
    if ratio >= model(hi):
        return hi
    for _ in range(60):  # model(s) increases with s
        mid = 0.5 * (lo + hi)
        lo, hi = (mid, hi) if model(mid) < ratio else (lo, mid)
    return 0.5 * (lo + hi)


def _zeta_space(cfg, comm, geo, earlier=(), kept: dict | None = None) -> tuple[float, object | None]:
    """Estimate of zeta's space error on ``geo``, from its differences to ``earlier`` meshes that ``geo`` refines
    (the coarsest first), with e(N) = A N^-s over the number of cells N:
    - two earlier meshes a, b: s observed from the two differences (:func:`observed_exponent`: at least 1/2, a
      rate of 1 in h, at most (q + 1) / 2, the best rate of zeta's degree q in L2), and
      e = D_bc / ((N_c / N_b)^s - 1);
    - one: s = 1/2 (rho = sqrt(N_b / N_c), e = D rho / (1 - rho));
    - none: from ``geo``'s uniform refinement, e = 2 D (s = 1/2, N_c / N_b = 4).
    ``kept``: the runs already made (:func:`_zeta_runs`). Returns the estimate (0 without damage: nothing is run)
    and the uniform refinement (or None)."""

    if not cfg.damage.enabled:
        return 0.0, None
    finer = None if earlier else refine_uniformly(geo)
    meshes = [*earlier[-2:], geo] if earlier else [geo, finer]
    runs = _zeta_runs(cfg, comm, meshes, {} if kept is None else kept)
    cells = [m.num_cells() for m in meshes]
    if finer is not None:
        return 2.0 * _zeta_difference(runs[0], runs[1], comm), finer
    d_bc = _zeta_difference(runs[-2], runs[-1], comm)
    s = 0.5
    if len(runs) == 3:
        s = observed_exponent(tuple(cells), _zeta_difference(runs[0], runs[1], comm), d_bc,
                              cfg.discretization.zeta_degree)
    return d_bc / ((cells[-1] / cells[-2]) ** s - 1.0), None


@dataclass
class _Step:
    """The step the pilot runs on the start mesh choose, and what they measured."""

    k0: float  # the pilots' coarsest step (T / N0, halved while the scheme could not take it)
    k: float  # the chosen step, k0 / 2^j
    rate: float  # the observed order in k
    error: float  # the time error's bound at k
    times: np.ndarray  # the levels of the time error's profile
    profile: np.ndarray  # the time error at k on those levels
    growth: float  # eta's largest level over its level 0 (the first pilot)
    worst_t: float  # the time of that level


class _Planner:
    """One plan (:func:`plan`), in the module docstring's order: the step (:meth:`_step`), the degree
    (:meth:`_degree`), u's mesh (:meth:`_mesh`) and zeta's part (:meth:`_fit_zeta`). Holds what the stages
    share: the scene (loaded once; each candidate is a ``replace()`` of it), the absolute tolerance, the constants
    C per degree, each degree's sequence of solved meshes and the zeta runs already made."""

    def __init__(self, scene, comm: MPI.Comm, log) -> None:

        self.t_start = time.perf_counter()
        self.scene, self.comm, self.log = scene, comm, log
        self.acc = acc = scene.accuracy
        if not acc.enabled:
            raise ValueError("plan: the scene has no accuracy.tolerance")
        cfg = _with(scene, {"output": {"xdmf": False}})
        self.start = _start_mesh(cfg, comm)
        self.order = _order(_with(cfg, self.start))
        self.T = cfg.time.T
        self.base = _with(cfg, self.start, {"time": {"order": self.order}})
        self.geo0 = build(comm, self.base.mesh, cfg.boundaries, cfg.dim)
        two_mu = cfg.material.E / (1.0 + cfg.material.nu)
        self.Cs = {d: C_TIMES_2MU[d] / two_mu for d in acc.degrees}
        self.tol = acc.tolerance
        if acc.relative:
            lv = _Level0(_with(self.base, degrees(max(acc.degrees))), comm, self.geo0)
            self.tol = acc.tolerance * lv.strain_norm
            log(f"tolerance {acc.tolerance:g} x ||eps(u_0)|| = {self.tol:.4g}")
        self.max_dofs, self.limit = dof_limit(acc, comm)
        self.seqs: dict[int, list[dict]] = {d: [] for d in acc.degrees}
        self.runs: dict = {}  # zeta's runs, by (mesh, step)
        # set by plan(): what a mesh is solved with (the t = 0 problem or coarse-step runs), eta's growth factor
        # applied to its estimate, and the scene of those solves
        self.level, self.g, self.over = _Level0, 1.0, self.base

    @property
    def G(self) -> float:
        """The factor on u's estimate for its largest level: eta's growth over the run, at least 1."""
        return max(self.g, 1.0)

    def plan(self) -> Plan:
        step = self._step()
        # the space parts get what the chosen step leaves of TOL (the steps are T / (N0 2^j): the time part is
        # often far below its share)
        share = self.tol - step.error
        # the space estimate: the t = 0 problem times the growth, or, where eta grows more than GROWTH_AT_0 (a
        # load that starts small), coarse-step runs to the level of largest eta (their largest eta counts)
        at_k0 = _with(self.base, _k(step.k0))
        self.over, self.level, self.g = at_k0, _Level0, step.growth
        if step.growth > GROWTH_AT_0:
            self.over, self.level, self.g = _with(at_k0, {"time": {"T": step.worst_t}}), _Worst, 1.0
            self.log(f"  the mesh is adapted to the level of largest eta, t = {step.worst_t:g}")
        degree, (geo, eta2) = self._degree(share)
        geo, eta2 = self._mesh(degree, share, geo, eta2)
        # zeta's runs go to the scene's T at the pilots' coarsest step
        geo, zeta_space = self._fit_zeta(degree, share, geo, eta2, _with(at_k0, degrees(degree)))
        estimate = {"space_u": self.seqs[degree][-1]["estimate"] * self.G, "space_zeta": zeta_space, "time": step.error}
        out = Plan(self.tol, degree, self.order, step.k, geo, self.start, estimate, self.Cs[degree], step.growth,
                   step.rate, (step.times, step.profile), [r for d in self.acc.degrees for r in self.seqs[d]],
                   scene=self.scene)
        out.seconds = time.perf_counter() - self.t_start
        self.log(f"chosen: P{degree} (u and zeta), order {self.order}, k = {step.k:g} ({round(self.T / step.k)} "
                 f"steps), {geo.num_cells()} cells; estimated error <= {sum(estimate.values()):.3e} (space "
                 f"{estimate['space_u'] + zeta_space:.3e}, time {estimate['time']:.3e}) for TOL {self.tol:.3e}; "
                 f"planned in {out.seconds:.1f} s")
        return out

    def _step(self) -> _Step:
        """Step doubling on the start mesh with the lowest degree (the time error hardly depends on it; P1 is the
        cheapest), which also gives how eta evolves over the run; the largest T / (N0 2^j) whose time error is
        within SAFETY times its share."""
        k0 = self.T / N0
        pilot = _with(self.base, degrees(min(self.acc.degrees)))
        for _ in range(6):  # a start step the scheme cannot take is halved, and the three runs start again
            try:
                pilots = [_Pilot(_with(pilot, _k(k0 / 2**j)), self.comm, self.geo0,
                                 estimate=(j == 0)) for j in range(3)]
                break
            except SolveFailure:
                k0 /= 2
        else:
            raise ToleranceError(self.tol, math.nan, 0, "time.k (no pilot step converged)")
        p, e_k4, ts, profile = _time_estimate(pilots, self.order, self.comm)
        eta = np.array(pilots[0].eta)
        worst = int(np.argmax(eta))
        growth = float(eta[worst] / eta[0]) if eta[0] > 0 else math.inf
        self.log(f"start mesh: time error of k = {k0 / 4:g}: {e_k4:.3e} (order {p:.2f}); eta grows x{growth:.3g} "
                 f"over the run")
        share = (1.0 - self.acc.space_share) * self.tol
        j, k4 = 0, k0 / 4
        while e_k4 > 0 and e_k4 * ((k0 / 2**j) / k4) ** p > SAFETY * share:
            j += 1
            if j > 20:
                raise ToleranceError(self.tol, e_k4, 0, "time.k")
        k = k0 / 2**j
        scale = (k / k4) ** p if e_k4 > 0 else 0.0
        return _Step(k0, k, p, e_k4 * scale, ts, profile * scale, growth, pilots[0].t[worst])

    def _degree(self, share: float) -> tuple[int, tuple]:
        """One solve of each degree on the start mesh; the one whose predicted cost per step (the dofs it needs by
        its adapted rate, times its cost per dof) is lowest. Returns it and (mesh, eta_K^2) of its solve."""
        last, cost = {}, {}
        for d in self.acc.degrees:
            last[d] = self._adapt(self.over, d, share / self.g, geo=self.geo0, max_steps=1)
            first = self.seqs[d][0]
            needed = first["dofs"] * max(first["estimate"] * self.g / share, 1.0) ** (1.0 / ADAPTED_RATE[d])
            cost[d] = COST_PER_DOF[d] * needed
        degree = min(self.acc.degrees, key=lambda d: cost[d])
        self.log("predicted cost per step (P1-dof units): " + ", ".join(f"P{d} {cost[d]:.4g}" for d in self.acc.degrees)
                 + f" -> P{degree}")
        self._refuse_beyond_reach(share)
        return degree, last[degree]

    def _refuse_beyond_reach(self, share: float) -> None:
        """Refuse at once a tolerance whose predicted dofs (error ~ dofs^-rate from each degree's first mesh) exceed
        the limit for every degree, instead of refining for hours towards it."""
        needed = {}
        for d in self.acc.degrees:
            first = self.seqs[d][0]
            needed[d] = first["dofs"] * max(first["estimate"] * self.g / share, 1.0) ** (1.0 / ADAPTED_RATE[d])
        best = min(needed, key=needed.get)
        if needed[best] > self.max_dofs:
            first = self.seqs[best][0]
            raise ToleranceError(self.tol, first["estimate"] * self.g, first["dofs"], self.limit, target=share,
                                 predicted=needed[best])

    def _mesh(self, degree: int, share: float, geo, eta2) -> tuple:
        """u's mesh: adapted on from the degree's probe until C eta_0 growth is within (1 - ZETA_SHARE) of the
        space share."""
        target = (1.0 - ZETA_SHARE) * share / self.G
        if self.seqs[degree][-1]["estimate"] > target:
            geo, eta2 = self._adapt(self.over, degree, target, marked=(geo, eta2))
        return geo, eta2

    def _fit_zeta(self, degree: int, share: float, geo, eta2, run_k0) -> tuple:
        """zeta's space error on ``geo``, from its differences to up to two earlier meshes of the sequence (each with
        at most a quarter of the next one's cells) or to its uniform refinement. While the two space parts exceed
        the share: where zeta's part leaves room, a Dörfler step for u first (:meth:`_make_room`); else (or if that
        step does not fit) the mesh is refined uniformly (the earlier runs are kept, not repeated). Returns the
        mesh and zeta's bound on it."""

        seq, C, G = self.seqs[degree], self.Cs[degree], self.G
        chain: list = []  # the coarsest first
        for r in reversed(seq):
            if "_geo" in r and len(chain) < 2 and r["cells"] * 4 <= (chain[0] if chain else geo).num_cells():
                chain.insert(0, r["_geo"])
        zeta_space, finer = _zeta_space(run_k0, self.comm, geo, chain, self.runs)
        self.log(f"  zeta's space error on it <= {zeta_space:.3e}")
        while seq[-1]["estimate"] * G + zeta_space > share:
            if zeta_space <= ROOM_ZETA_MAX * share:
                room = self._make_room(degree, share, run_k0, geo, eta2, zeta_space)
                if room is not None:
                    return room
            if finer is None:
                finer = refine_uniformly(geo)
            if finer.num_cells() * degree**2 > self.max_dofs:  # 2-D: about p^2 dofs per cell
                raise ToleranceError(self.tol, zeta_space, finer.num_cells(),
                                     f"{self.limit} (the damage's space error)", target=share - seq[-1]["estimate"] * G)
            chain, geo = [*chain, geo][-2:], finer
            zeta_space, finer = _zeta_space(run_k0, self.comm, geo, chain, self.runs)
            lv = self.level(_with(self.over, degrees(degree)), self.comm, geo)
            eta2 = lv.eta2
            seq.append({"degree": degree, "cells": geo.num_cells(), "dofs": lv.dofs, "eta": lv.eta,
                        "estimate": C * lv.eta, "uniform": True})
            self.log(f"  refined uniformly: {geo.num_cells()} cells, C eta = {seq[-1]['estimate']:.3e}, zeta's space "
                     f"error <= {zeta_space:.3e}")
        return geo, zeta_space

    def _make_room(self, degree: int, share: float, run_k0, geo, eta2, zeta_space: float):
        """A Dörfler step for u that leaves zeta's part room within the space share, instead of a uniform refinement.

        On the mesh M (``geo``, with its eta_K^2) zeta's error is at most ``zeta_space``; u is adapted on from M to
        C eta G <= share - (1 + ROOM_MARGIN) zeta_space, giving M' that refines M. By the triangle inequality zeta's
        error on M' is at most zeta_space + D, with D = max over levels of ||zeta_M' - zeta_M|| (runs at the same
        step as the estimate's on M: the time error cancels). Taken if C eta' G + zeta_space + D <= share; returns
        (M', zeta_space + D), or None (M' is then dropped, and the caller refines M uniformly)."""
        seq, G = self.seqs[degree], self.G
        n = len(seq)
        target = (share - (1.0 + ROOM_MARGIN) * zeta_space) / G
        finer, _ = self._adapt(self.over, degree, target, marked=(geo, eta2))
        bound = zeta_space
        if run_k0.damage.enabled:
            bound += _zeta_difference(*_zeta_runs(run_k0, self.comm, [geo, finer], self.runs), self.comm)
        total = seq[-1]["estimate"] * G + bound
        self.log(f"  a Dörfler step for u: {finer.num_cells()} cells, C eta = {seq[-1]['estimate']:.3e}, zeta's "
                 f"space error <= {bound:.3e}: {'taken' if total <= share else 'over the share, refined uniformly instead'}")
        if total <= share:
            return finer, bound
        del seq[n:]
        return None

    def _adapt(self, scene, degree: int, target: float, geo=None, max_steps: int | None = None,
               marked: tuple | None = None) -> tuple:
        """Dörfler-refine until C eta <= target (or ``max_steps`` meshes solved), appending each mesh's record to
        the degree's sequence; beyond ``accuracy.max_dofs``, a ToleranceError for the user's tolerance. Starts on
        ``geo``, or refines ``marked`` (geo, eta_K^2: a mesh already solved, the sequence's last) first. Returns
        the last mesh and its eta_K^2."""

        seq, C, acc = self.seqs[degree], self.Cs[degree], self.acc

        def refined(mesh, eta2):
            return refine(mesh, np.flatnonzero(dorfler(eta2, _theta(acc.theta, seq[-1]["estimate"] / target),
                                                       self.comm)))

        if marked is not None:
            geo = refined(*marked)
        solved = 0
        while True:
            lv = self.level(_with(scene, degrees(degree)), self.comm, geo)
            rec = {"degree": degree, "cells": lv.model.geo.num_cells(), "dofs": lv.dofs, "eta": lv.eta,
                   "estimate": C * lv.eta, "_geo": lv.model.geo}
            seq.append(rec)
            solved += 1
            self.log(f"  P{degree}: {rec['cells']} cells, {rec['dofs']} dofs, C eta = {rec['estimate']:.3e} "
                     f"(target {target:.3e})")
            if rec["estimate"] <= target or (max_steps is not None and solved >= max_steps):
                return lv.model.geo, lv.eta2
            if rec["dofs"] > self.max_dofs:
                raise ToleranceError(self.tol, rec["estimate"], rec["dofs"], self.limit, target=target)
            geo = refined(lv.model.geo, lv.eta2)


def memory_dofs(comm: MPI.Comm) -> int:
    """The displacement dofs that fit in MEMORY_SHARE of the memory of the machines the ranks run on
    (each node counted once), at BYTES_PER_DOF."""
    import os
    import socket

    try:
        mine = os.sysconf("SC_PHYS_PAGES") * os.sysconf("SC_PAGE_SIZE")
    except (ValueError, OSError):
        return 2**62
    nodes = dict(comm.allgather((socket.gethostname(), mine)))
    return int(MEMORY_SHARE * sum(nodes.values()) / BYTES_PER_DOF)


def dof_limit(acc, comm: MPI.Comm) -> tuple[int, str]:
    """The planner's limit on the dofs of a mesh and the setting it comes from: accuracy.max_dofs, or the memory."""
    mem = memory_dofs(comm)
    if mem < acc.max_dofs:
        return mem, f"the memory ({mem} dofs fit in {MEMORY_SHARE:.0%} of it; accuracy.max_dofs = {acc.max_dofs})"
    return acc.max_dofs, "accuracy.max_dofs"


def plan(scene, comm: MPI.Comm, log=print) -> Plan:
    """Choose degree, mesh and step for the scene's ``accuracy.tolerance`` (collective): ``scene`` is a Config,
    and the run's is ``plan(...).config``."""
    return _Planner(scene, comm, log).plan()


class ErrorSensor:
    """The run's estimated error per level: C eta_n (+ zeta's bound) and the time error of the plan (CSV columns)."""

    columns = ("est_space", "est_time")

    def __init__(self, model, plan: Plan) -> None:

        self.est = estimator_for(model)
        self.plan = plan
        self.worst = {"space": 0.0, "time": 0.0, "total": 0.0}

    def __call__(self, row: dict) -> dict:
        space = self.plan.C * self.est.total() + self.plan.estimate["space_zeta"]
        tim = self.plan.time_error(row["t"])
        self.worst["space"] = max(self.worst["space"], space)
        self.worst["time"] = max(self.worst["time"], tim)
        self.worst["total"] = max(self.worst["total"], space + tim)
        return {"est_space": space, "est_time": tim}
