"""The planner: the degree, the mesh and the step that bring the paper's error below a tolerance
(docs/guide/accuracy.md; the norm: docs/model.md §3.6).

The error is bounded by a space part and a time part (``accuracy.space_share`` of the tolerance bounds the
space part, the rest the time part). In order:

1. the step (:func:`time_error.choose_step`): step doubling on the start mesh with the lowest degree; the space
   parts then get what its time error leaves of the tolerance. With ``accuracy.time = "adaptive"``
   (:func:`time_error.controller_step`) the run's step controller keeps the time error within the time's share
   instead, and one pilot run replaces the three;
2. the degree (:meth:`Planner._degree`): one solve per degree on the start mesh; the measured rates of adapted
   meshes extrapolate the dofs each needs, times its cost per dof (``constants``);
3. u's mesh (:meth:`Planner._mesh`): Dörfler refinement until C eta, times the indicator's growth over the run,
   is within its part; the solves are those of a :class:`solves.SpaceProbe` (the t = 0 problem, or coarse-step
   runs to the level of largest indicator where it grows more than GROWTH_AT_0); far from the target a round refines
   the few cells that carry most of eta^2 (singular corners) twice (CORNER_RATIO, CORNER_THETA).
   Each solve starts from the previous mesh's solution; on the way the estimator's constant is calibrated on the
   scene (:mod:`calibration`) and zeta's part measured on a mesh about an eighth of the final one, u then aiming at
   what it leaves of the share;
4. zeta's part (:meth:`Planner._fit_zeta`, :mod:`zeta`), where that measured part is over ZETA_SHARE of the share:
   while the two space parts exceed the share, a Dörfler step for u that leaves zeta's part room, else a uniform
   refinement.
The ingredients' changes of the answer (:mod:`ingredients`) are measured after the step; with
``accuracy.simplify`` the plan is made again for the scene without those it leaves out.

The damage's degree follows the displacement's; the order in time is 2 where the scene allows it. The mesh is
then fixed for the run.
"""

from __future__ import annotations

import math
import time
from collections.abc import Callable
from dataclasses import dataclass, replace

import numpy as np
from mpi4py import MPI

from solver.config import Config
from solver.errors import ToleranceError
from solver.mesh.adapt import refine, refine_twice, refine_uniformly
from solver.mesh.geometry import Geometry, build
from solver.physics.estimator import dorfler

from .calibration import Calibration, calibrate
from .constants import COST_PER_DOF, adapted_rate, c_times_2mu
from .ingredients import SIMPLIFY_FRACTION, Ingredient, at_step, degree_change, pilot_changes, simplified, without
from .memory import dof_limit
from .records import ErrorEstimate, MeshRecord, Plan
from .scene import degrees, start_mesh, step, time_order, with_changes
from .solves import AtLargestLevel, AtLevel0, PilotRun, SpaceProbe, solve_level0
from .time_error import StepChoice, choose_step, controller_step, first_pilot, restep
from .zeta import ZetaRuns, zeta_difference, zeta_space

Log = Callable[[str], None]

GROWTH_AT_0 = 1.5  # the indicator growing more over the run: adapt to its largest level instead of t = 0
THETA_MAX = 0.95  # the largest Dörfler fraction (far from the target)
ZETA_SHARE = 0.3  # of the space share, left to the damage's space error while the mesh is adapted
# zeta's part over ZETA_SHARE but at most ROOM_ZETA_MAX of the space share: u's mesh is adapted on to make room
# (ROOM_MARGIN of zeta's part kept for its change on the new mesh) before any uniform refinement
ROOM_ZETA_MAX = 0.6
ROOM_MARGIN = 0.25
# zeta's part is measured on the adaptive sequence's mesh once the mesh u needs is predicted within ZETA_PROBE_RATIO
# times its cells (runs at the pilots' coarsest step on a mesh about an eighth of the final one; on Example 1 at 1e-4 a
# thirtieth gave a bound of 2.1e-5 where an eighth gave 1.6e-6, and the tighter target for u cost more than it saved;
# a sixteenth, the 2,194-cell mesh, gave 4.7e-6: zeta's runs cost about a third less, u's mesh grew from 8,868 cells and
# 48 steps to 9,272 and 49, and the run paid about what the planning saved)
ZETA_PROBE_RATIO = 8.0
# the estimator's constant is calibrated on the scene (:func:`calibration.calibrate`) on the sequence's first mesh whose
# predicted final mesh is within CALIBRATE_RATIO times its cells (its uniform refinement: a thirtieth of the final mesh)
CALIBRATE_RATIO = 128.0
# a mesh over u's target is kept, and the step made smaller to leave it room within the tolerance, where that takes at
# most STEPS_PER_ROUND more steps of the run: another Dörfler round (a model build, a factorization and an estimate of
# the whole mesh) costs more than that (Example 1 at 1e-4: a round on 8,666 P2 cells about 1.4 s, a step of the run
# about 0.2 s)
STEPS_PER_ROUND = 4
# the same for the run's step controller (accuracy.time = "adaptive"), whose steps are not known before the run: its
# tolerance made smaller by at most the factor that adds this fraction of its steps (about STEPS_PER_ROUND of 40)
MORE_STEPS_ADAPTIVE = 0.1
# a Dörfler set of at most SMALL_SET of the cells (the estimate carried by a few cells at singular corners, near the
# end of a 2-D sequence) is refined twice in one round (its children again): such a set's first refinement cut eta
# only 1.2-1.6-fold each round on Example 1 (8,495 -> 8,569 -> 8,666 -> 8,742 P2 cells, one factorization of the
# whole mesh each), and refining its children too adds some hundred cells
SMALL_SET = 0.02
# far from the target (an estimate over CORNER_RATIO times it, so that one halving of eta cannot reach it), the
# smallest set carrying CORNER_THETA of eta^2, where it is at most SMALL_SET of the cells (the singular corners), is
# refined twice in the round and the rest of the Dörfler set once: one such round cut eta 2.5-3.1-fold on Example 1
# where a plain round cut it 1.95-2.0-fold, and at 1e-4 the sequence went ... 4,260 -> 8,495 -> 8,868 cells (two
# factorizations of 35,000 dofs) and now ... 4,288 -> 9,148 (one); with CORNER_THETA 0.3 or 0.6 the last round
# overshot and took one more (14,141 and 12,261 cells), with 0.5 it ended at 9,997
CORNER_RATIO = 2.0
CORNER_THETA = 0.4


def dorfler_fraction(theta: float, ratio: float) -> float:
    """The Dörfler fraction for an estimate ``ratio`` times its target: the cells carrying 1 - 1/ratio^2 of
    eta^2 (refining them all away would leave the target's eta^2), at least ``theta`` and at most THETA_MAX, so
    that few solve-estimate-refine rounds are needed (each is a mesh to build). Near the target (1 - 1/ratio^2
    below theta / 2) twice that share instead of theta: a mesh a few per cent over its target is refined a little,
    not by half (which overshoots the target, and the run pays for the cells)."""
    needed = 1.0 - 1.0 / ratio**2
    return min(THETA_MAX, max(needed, min(theta, 2.0 * needed)))


@dataclass(frozen=True)
class Setup:
    """What every stage of a plan starts from."""

    scene: Config  # the scene planned for
    start: dict  # the start mesh's changes to the scene
    order: int  # the time scheme's order
    base: Config  # the scene on the start mesh, at ``order``, without XDMF output
    geo0: Geometry  # the start mesh
    constants: dict[int, float]  # C per degree for the scene's material
    tol: float  # the absolute tolerance
    max_dofs: int  # no mesh beyond it
    limit: str  # the setting ``max_dofs`` comes from
    started: float  # perf_counter at the start of planning


def prepare(scene: Config, comm: MPI.Comm, log: Log) -> Setup:
    """The start mesh, the order, the constants, the absolute tolerance (a relative one times ||eps(u_0)||, one
    solve) and the dof limit. Collective."""
    started = time.perf_counter()
    if not scene.accuracy.enabled:
        raise ValueError("plan: the scene has no accuracy.tolerance")
    acc = scene.accuracy
    cfg = with_changes(scene, {"output": {"xdmf": False}})
    start = start_mesh(cfg, comm)
    order = time_order(with_changes(cfg, start))
    base = with_changes(cfg, start, {"time": {"order": order}})
    geo0 = build(comm, base.mesh, cfg.boundaries, cfg.dim)
    two_mu = cfg.material.E / (1.0 + cfg.material.nu)
    constants = {d: c_times_2mu(geo0.dim)[d] / two_mu for d in acc.degrees}
    tol = acc.tolerance
    if acc.relative:
        tol = acc.tolerance * solve_level0(with_changes(base, degrees(max(acc.degrees))), comm, geo0).strain_norm
        log(f"tolerance {acc.tolerance:g} x ||eps(u_0)|| = {tol:.4g}")
    max_dofs, limit = dof_limit(acc, comm)
    return Setup(scene, start, order, base, geo0, constants, tol, max_dofs, limit, started)


class Planner:
    """One plan from a :class:`Setup` (:meth:`plan` runs it). Holds what the stages share: each degree's sequence
    of solved meshes and the zeta runs already made."""

    def __init__(self, setup: Setup, comm: MPI.Comm, log: Log, first: PilotRun | None = None,
                 changes: list[Ingredient] | None = None) -> None:
        """``first``: the coarsest pilot of the scene, already run (:func:`time_error.first_pilot`); ``changes``: the
        ingredients' changes already measured, the order's at that pilot's step (the simplified scene's plan gets
        both from the full scene's, :meth:`_simplified`)."""
        self.setup, self.comm, self.log = setup, comm, log
        self.first, self.known = first, changes
        self.acc = setup.scene.accuracy
        self.seqs: dict[int, list[MeshRecord]] = {d: [] for d in self.acc.degrees}
        self.runs = ZetaRuns()
        self.models: dict = {}  # per degree, the last level-0 model solved (the next nested solve's start)
        self.C = dict(setup.constants)  # per degree, the estimator's constant (stored, then calibrated)
        self.calibrated: set[int] = set()
        self.calibration: Calibration | None = None
        self.stages: dict[str, float] = {}  # seconds per stage of the plan
        self.chosen: StepChoice | None = None  # the step (made smaller where a mesh over u's target was kept)

    def plan(self) -> Plan:
        """The stages in the module docstring's order. Collective."""
        s, acc = self.setup, self.acc
        pilot = with_changes(s.base, degrees(min(acc.degrees)))  # the time error hardly depends on the degree
        started = time.perf_counter()
        self.stages["prepare"] = started - s.started
        if acc.simplify and self.known is None:
            # the ingredients first (on the coarsest pilot): a simplified scene is planned without the full scene's
            # step doubling, from the run without what it leaves out
            first = self.first or first_pilot(pilot, self.comm, s.geo0, s.tol)
            self._time("step", started)
            started = time.perf_counter()
            k0, runs = first.model.cfg.time.k, {}
            measured = pilot_changes(first, with_changes(pilot, step(k0)), self.comm, s.geo0, s.order, k0, k0, runs)
            self._time("ingredients", started)
            marked, left_out = simplified(measured, s.tol)
            if left_out > 0.0:
                return self._simplified(marked, left_out, runs)
            self.first, self.known = first, marked
            started = time.perf_counter()
        by = controller_step if acc.time == "adaptive" else choose_step
        chosen = by(pilot, self.comm, s.geo0, s.order, (1.0 - acc.space_share) * s.tol, s.tol, self.log, self.first)
        self._time("step", started)
        self.chosen = chosen
        # the controller's steps are not known before the run: the order's change at the pilot's step, unscaled
        k_order = chosen.k0 if chosen.adaptive else chosen.k
        if self.known is not None:
            changes = at_step(self.known, chosen.k0, k_order)
        else:
            started = time.perf_counter()
            changes = pilot_changes(chosen.pilot, with_changes(pilot, step(chosen.k0)), self.comm, s.geo0, s.order,
                                    chosen.k0, k_order)
            self._time("ingredients", started)
        # the space parts get what the chosen step leaves of TOL
        share = s.tol - chosen.error
        at_k0 = with_changes(s.base, step(chosen.k0))
        probe: SpaceProbe = AtLevel0(at_k0, chosen.growth)
        if chosen.growth > GROWTH_AT_0:
            probe = AtLargestLevel(with_changes(at_k0, {"time": {"T": chosen.largest_t}}))
            self.log(f"  the mesh is adapted to the level of largest eta, t = {chosen.largest_t:g}")
        started = time.perf_counter()
        degree, (geo, cells) = self._degree(probe, share)
        self._time("degree", started)
        # zeta's runs go to the scene's T at the pilots' coarsest step
        run_k0 = with_changes(at_k0, degrees(degree))
        started = time.perf_counter()
        geo, cells, zeta_bound = self._mesh(probe, degree, share, geo, cells, run_k0)
        if zeta_bound is None:
            geo, zeta_bound = self._fit_zeta(probe, degree, share, geo, cells, run_k0)
        self.stages["mesh"] = (time.perf_counter() - started - self.stages.get("zeta", 0.0)
                               - self.stages.get("calibration", 0.0))
        chosen = self.chosen
        estimate = ErrorEstimate(self.seqs[degree][-1].estimate * probe.factor, zeta_bound, chosen.error)
        started = time.perf_counter()
        changes = [*changes, *self._degree_change(probe, degree, geo)]
        self._time("ingredients", started)
        last = self.models.get(degree)
        level0_u = last.u.x.array.copy() if isinstance(probe, AtLevel0) and last is not None and last.geo is geo \
            else None
        seconds = time.perf_counter() - s.started
        out = Plan(s.tol, degree, s.order, chosen.k, geo, s.start, estimate, self.C[degree], chosen.growth,
                   chosen.rate, (chosen.times, chosen.profile), tuple(r for d in acc.degrees for r in self.seqs[d]),
                   seconds, s.scene, dict(self.stages), self.calibration, tuple(changes), level0_u,
                   adaptive=chosen.adaptive)
        steps = (f"adaptive steps from k = {chosen.k:g}, time.tolerance = {chosen.error:.3e}" if chosen.adaptive
                 else f"k = {chosen.k:g} ({round(s.base.time.T / chosen.k)} steps)")
        self.log(f"chosen: P{degree} (u and zeta), order {s.order}, {steps}, {geo.num_cells()} cells; estimated error <= "
                 f"{estimate.total:.3e} (space {estimate.space_u + zeta_bound:.3e}, time {estimate.time:.3e}) for "
                 f"TOL {s.tol:.3e}; planned in {seconds:.2f} s ("
                 + ", ".join(f"{k} {v:.2f}" for k, v in self.stages.items()) + ")")
        return out

    def _simplified(self, changes: list, left_out: float, runs: dict) -> Plan:
        """The plan of the scene without the ingredients ``changes`` marks dropped, for the tolerance less their
        changes (``left_out``); the result is the full model's within the tolerance. The plan keeps the user's
        tolerance, the ingredients' report and the changes left out as the estimate's ``model`` part. It starts
        from what the full scene's measured: the start mesh, the run without the one ingredient left out (``runs``,
        its first pilot) and the changes of those kept (not measured again)."""
        s = self.setup
        scene = s.scene
        for i in changes:
            if i.dropped:
                scene = without(scene, i.name)
        names = ", ".join(i.name for i in changes if i.dropped)
        self.log(f"accuracy.simplify: left out {names} (changing the answer by {left_out:.2e} together, "
                 f"{left_out / s.tol:.2g} TOL <= {SIMPLIFY_FRACTION:g} TOL); planned for TOL - {left_out:.2e}")
        scene = scene.replace({"accuracy": {"tolerance": s.tol - left_out, "relative": False, "simplify": False}},
                              label="accuracy.simplify")
        setup = prepare(scene, self.comm, self.log)
        dropped = [i.name for i in changes if i.dropped]
        first = None
        if setup.start == s.start and setup.order == s.order:
            setup = replace(setup, geo0=s.geo0)  # the same start mesh: the pilot runs' arrays are on it
            first = runs.get(dropped[0]) if len(dropped) == 1 else None
        inner = Planner(setup, self.comm, self.log, first, [i for i in changes if not i.dropped]).plan()
        seconds = time.perf_counter() - s.started
        est = replace(inner.estimate, model=left_out)
        kept = {i.name: i for i in inner.ingredients}
        report = tuple(i if i.dropped else kept.get(i.name, i) for i in changes) + tuple(
            i for i in inner.ingredients if i.name not in {c.name for c in changes})
        stages = {k: self.stages.get(k, 0.0) + inner.stages.get(k, 0.0) for k in {*self.stages, *inner.stages}}
        return replace(inner, tolerance=s.tol, estimate=est, seconds=seconds, stages=stages, ingredients=report)

    def _degree_change(self, probe: SpaceProbe, degree: int, geo: Geometry) -> list:
        """P2 over P1 on the chosen mesh (a P1 solve at t = 0 beside the last P2 one), where P2 was chosen and the
        last solve is the t = 0 problem on that mesh; [] where P1 was chosen."""
        if degree != 2:
            return []
        last = self.models.get(2)
        if not isinstance(probe, AtLevel0) or last is None or last.geo is not geo:
            return [Ingredient("degree", math.nan, "P2 over P1: not measured (the mesh was fitted to a later level)")]
        p1 = probe.solve(1, self.comm, geo, last)
        return [Ingredient("degree", degree_change(p1.model, last, self.comm), "P2 over P1: t = 0 solves on the "
                           "chosen mesh")]

    def _needed_dofs(self, degree: int, growth: float, share: float) -> float:
        """The dofs the degree's first mesh predicts for ``share`` by its adapted rate (error ~ dofs^-rate)."""
        first = self.seqs[degree][0]
        return first.dofs * max(first.estimate * growth / share, 1.0) ** (1.0 / adapted_rate(self.setup.geo0.dim)[degree])

    def _degree(self, probe: SpaceProbe, share: float) -> tuple[int, tuple]:
        """One solve of each degree on the start mesh; the one whose predicted cost per step (the dofs it needs,
        times its cost per dof) is lowest. Returns it and (mesh, eta_K^2) of its solve."""
        last, cost = {}, {}
        for d in self.acc.degrees:
            last[d] = self._adapt(probe, d, share / probe.growth, geo=self.setup.geo0, max_steps=1)
            cost[d] = COST_PER_DOF[d] * self._needed_dofs(d, probe.growth, share)
        degree = min(self.acc.degrees, key=lambda d: cost[d])
        self.log("predicted cost per step (P1-dof units): " + ", ".join(f"P{d} {cost[d]:.4g}" for d in self.acc.degrees)
                 + f" -> P{degree}")
        self._refuse_beyond_reach(probe, share)
        return degree, last[degree]

    def _refuse_beyond_reach(self, probe: SpaceProbe, share: float) -> None:
        """Refuse at once a tolerance whose predicted dofs exceed the limit for every degree, instead of refining
        for hours towards it."""
        needed = {d: self._needed_dofs(d, probe.growth, share) for d in self.acc.degrees}
        best = min(needed, key=needed.get)
        if needed[best] > self.setup.max_dofs:
            first = self.seqs[best][0]
            raise ToleranceError(self.setup.tol, first.estimate * probe.growth, first.dofs, self.setup.limit,
                                 target=share, predicted=needed[best])

    def _mesh(self, probe: SpaceProbe, degree: int, share: float, geo: Geometry, cells: np.ndarray,
              run_k0: Config) -> tuple:
        """u's mesh: adapted on from the degree's probe until C eta times the growth G fits what zeta's part leaves of
        the space share. Without damage that is the whole share. With damage, zeta's part is measured on the
        sequence's mesh once the mesh u needs is predicted within ZETA_PROBE_RATIO times its cells (:meth:`_zeta_on`,
        nested runs at the pilots' step); if it is at most ZETA_SHARE of the share, u aims at share - that part, and
        the part counts for the finer meshes that refine it (zeta's error falls with the cells: e ~ cells^-s,
        s >= 1/2, as :mod:`.zeta` models it). Returns (mesh, eta_K^2, zeta's bound), the bound None where zeta's part
        is left to :meth:`_fit_zeta` (over ZETA_SHARE of the share)."""
        G = probe.factor
        damage = run_k0.damage.enabled
        target = (share if not damage else (1.0 - ZETA_SHARE) * share) / G
        found: list[float] = []

        def retarget(rec: MeshRecord, final: bool) -> float | None:
            predicted = rec.cells * max(rec.estimate / target, 1.0) ** (1.0 / adapted_rate(self.setup.geo0.dim)[degree])
            if degree not in self.calibrated and (final or predicted <= CALIBRATE_RATIO * rec.cells):
                self._calibrate(probe, degree)
                rec = self.seqs[degree][-1]
                final = rec.estimate <= target
                predicted = rec.cells * max(rec.estimate / target, 1.0) ** (1.0 / adapted_rate(self.setup.geo0.dim)[degree])
            if not damage or found:
                return None
            if not final and predicted > ZETA_PROBE_RATIO * rec.cells:
                return None
            bound = self._zeta_on(degree, rec.geo, run_k0)
            found.append(bound)
            if bound > ZETA_SHARE * share:
                return None
            return (share - bound) / G

        def zeta_part() -> float | None:
            """zeta's bound as this mesh counts it (0 without damage); None with damage where it is not yet measured
            or is over ZETA_SHARE of the share (:meth:`_fit_zeta`'s then)."""
            if damage and (not found or found[0] > ZETA_SHARE * share):
                return None
            return found[0] if found else 0.0

        def accept(rec: MeshRecord) -> bool:
            """A mesh over the target kept if the step, made smaller by at most STEPS_PER_ROUND steps, leaves its
            estimate room (:func:`time_error.restep`); then the plan's step is that one."""
            zeta = zeta_part()
            if zeta is None:
                return False
            T = run_k0.time.T
            smaller = restep(self.chosen, self.setup.tol - rec.estimate * G - zeta, T)
            if smaller is None:
                return False
            if self.chosen.adaptive:  # the controller's steps grow as its tolerance^(-1/order)
                if (self.chosen.error / smaller.error) ** (1.0 / smaller.rate) > 1.0 + MORE_STEPS_ADAPTIVE:
                    return False
            elif round(T / smaller.k) - round(T / self.chosen.k) > STEPS_PER_ROUND:
                return False
            if smaller is not self.chosen:
                what = (f"time.tolerance = {smaller.error:.3e}" if smaller.adaptive
                        else f"k = {smaller.k:g} ({round(T / smaller.k)} steps)")
                self.log(f"  kept, {rec.estimate / (target if not found else (share - zeta) / G):.3f} times u's "
                         f"target: {what} leaves it room")
            self.chosen = smaller
            return True

        geo, cells = self._adapt(probe, degree, target, marked=(geo, cells), retarget=retarget, solved_first=True,
                                 accept=accept)
        return geo, cells, zeta_part()

    def _calibrate(self, probe: SpaceProbe, degree: int) -> None:
        """C for this scene from the sequence's last mesh and its uniform refinement (:func:`calibration.calibrate`);
        the sequence's estimates are C times eta again. Only on the t = 0 problem (a probe that runs to the level of
        largest eta, and a 3-D mesh, whose uniform refinement has 8 times its cells and where the stored constant was
        measured above the tetrahedra's (docs/guide/accuracy.md), keep the stored constant, said in the log)."""
        self.calibrated.add(degree)
        if not isinstance(probe, AtLevel0) or self.models.get(degree) is None or self.setup.geo0.dim != 2:
            self.log(f"  P{degree}: the estimator's constant as stored, C = {self.C[degree]:.3g}")
            return
        started = time.perf_counter()
        cal = calibrate(probe, degree, self.comm, self.models[degree], self.seqs[degree][-1].indicator,
                        self.C[degree])
        self.calibration = cal
        self.C[degree] = cal.C
        self.seqs[degree][:] = [replace(r, estimate=cal.C * r.indicator) for r in self.seqs[degree]]
        self._time("calibration", started)
        self.log(f"  P{degree}: C = {cal.C:.3g} calibrated on {cal.cells} cells and their uniform refinement "
                 f"(difference {cal.difference:.3e}, eta ratio {cal.ratio:.3f}; stored {cal.stored:.3g})")

    def _keep_start(self, probe: SpaceProbe, degree: int, lv) -> None:
        """A t = 0 solution becomes the start of zeta's runs' level 0 on its mesh (:class:`zeta.ZetaRuns`): the
        same problem, solved already (a cold start there took the first contact's Newton path again)."""
        if isinstance(probe, AtLevel0):
            self.runs.start_from(lv.model.geo, degree, lv.model.u.x.array.copy())

    def _time(self, stage: str, started: float) -> None:
        self.stages[stage] = self.stages.get(stage, 0.0) + time.perf_counter() - started

    def _zeta_on(self, degree: int, geo: Geometry, run_k0: Config) -> float:
        """zeta's space error bound on ``geo`` (a mesh of the degree's sequence), from the sequence's earlier meshes
        it refines (each at most a quarter of the next one's cells) or its uniform refinement (:func:`zeta_space`)."""
        chain: list[Geometry] = []
        for r in reversed(self.seqs[degree]):
            if r.geo is not None and r.geo is not geo and len(chain) < 2 and \
                    r.cells * 4 <= (chain[0] if chain else geo).num_cells():
                chain.insert(0, r.geo)
        started = time.perf_counter()
        z = zeta_space(run_k0, self.comm, geo, chain, self.runs)
        self._time("zeta", started)
        self.log(f"  zeta's space error on {geo.num_cells()} cells <= {z.bound:.3e}")
        return z.bound

    def _fit_zeta(self, probe: SpaceProbe, degree: int, share: float, geo: Geometry, cells: np.ndarray,
                  run_k0: Config) -> tuple[Geometry, float]:
        """zeta's space error on ``geo``, from its differences to up to two earlier meshes of the sequence (each with
        at most a quarter of the next one's cells) or to its uniform refinement. While the two space parts exceed
        the share: where zeta's part leaves room, a Dörfler step for u first (:meth:`_make_room`); else (or if that
        step does not fit) the mesh is refined uniformly (the earlier runs are kept, not repeated). Returns the
        mesh and zeta's bound on it."""
        seq, C, G = self.seqs[degree], self.C[degree], probe.factor
        chain: list[Geometry] = []  # the coarsest first
        for r in reversed(seq):
            if r.geo is not None and len(chain) < 2 and r.cells * 4 <= (chain[0] if chain else geo).num_cells():
                chain.insert(0, r.geo)
        z = zeta_space(run_k0, self.comm, geo, chain, self.runs)
        self.log(f"  zeta's space error on it <= {z.bound:.3e}")
        while seq[-1].estimate * G + z.bound > share:
            if z.bound <= ROOM_ZETA_MAX * share:
                room = self._make_room(probe, degree, share, run_k0, geo, cells, z.bound)
                if room is not None:
                    return room
            finer = refine_uniformly(geo) if z.finer is None else z.finer
            if finer.num_cells() * degree**finer.dim > self.setup.max_dofs:  # about p^dim dofs per cell
                raise ToleranceError(self.setup.tol, z.bound, finer.num_cells(),
                                     f"{self.setup.limit} (the damage's space error)",
                                     target=share - seq[-1].estimate * G)
            chain, geo = [*chain, geo][-2:], finer
            z = zeta_space(run_k0, self.comm, geo, chain, self.runs)
            lv = probe.solve(degree, self.comm, geo, self.models.get(degree))
            self.models[degree] = lv.model
            self._keep_start(probe, degree, lv)
            cells = lv.cell_indicators
            seq.append(MeshRecord(degree, geo.num_cells(), lv.dofs, lv.indicator, C * lv.indicator, uniform=True))
            self.log(f"  refined uniformly: {geo.num_cells()} cells, C eta = {seq[-1].estimate:.3e}, zeta's space "
                     f"error <= {z.bound:.3e}")
        return geo, z.bound

    def _make_room(self, probe: SpaceProbe, degree: int, share: float, run_k0: Config, geo: Geometry,
                   cells: np.ndarray, zeta_bound: float) -> tuple[Geometry, float] | None:
        """A Dörfler step for u that leaves zeta's part room within the space share, instead of a uniform refinement.

        On the mesh M (``geo``, with its eta_K^2) zeta's error is at most ``zeta_bound``; u is adapted on from M to
        C eta G <= share - (1 + ROOM_MARGIN) zeta_bound, giving M' that refines M. By the triangle inequality zeta's
        error on M' is at most zeta_bound + D, with D = max over levels of ||zeta_M' - zeta_M|| (runs at the same
        step as the estimate's on M: the time error cancels). Taken if C eta' G + zeta_bound + D <= share; returns
        (M', zeta_bound + D), or None (M' is then dropped, and the caller refines M uniformly)."""
        seq, G = self.seqs[degree], probe.factor
        n, kept = len(seq), self.models.get(degree)
        target = (share - (1.0 + ROOM_MARGIN) * zeta_bound) / G
        finer, _ = self._adapt(probe, degree, target, marked=(geo, cells))
        bound = zeta_bound
        if run_k0.damage.enabled:
            bound += zeta_difference(*self.runs.on(run_k0, self.comm, [geo, finer]), self.comm)
        total = seq[-1].estimate * G + bound
        self.log(f"  a Dörfler step for u: {finer.num_cells()} cells, C eta = {seq[-1].estimate:.3e}, zeta's "
                 f"space error <= {bound:.3e}: {'taken' if total <= share else 'over the share, refined uniformly instead'}")
        if total <= share:
            return finer, bound
        del seq[n:]
        self.models[degree] = kept
        return None

    def _adapt(self, probe: SpaceProbe, degree: int, target: float, geo: Geometry | None = None,
               max_steps: int | None = None, marked: tuple | None = None,
               retarget: Callable[[MeshRecord, bool], float | None] | None = None,
               solved_first: bool = False, accept: Callable[[MeshRecord], bool] | None = None) -> tuple:
        """Dörfler-refine until C eta <= target (or ``max_steps`` meshes solved), appending each mesh's record to
        the degree's sequence; beyond the dof limit, a ToleranceError for the user's tolerance. Starts on ``geo``,
        or refines ``marked`` (geo, eta_K^2: a mesh already solved, the sequence's last) first. Each solve starts
        from the previous mesh's solution (nested: :func:`solves.warm_start`). ``retarget(record, final)``, after
        each solve, may give a new target (``final``: the record meets the old one); with ``solved_first``, it is
        asked first about ``marked`` itself. ``accept(record)``, for a record over the target: keep it all the same
        (the caller pays for it elsewhere). Returns the last mesh and its eta_K^2."""
        seq, theta = self.seqs[degree], self.acc.theta

        def refined(mesh: Geometry, cells: np.ndarray) -> Geometry:
            fraction = dorfler_fraction(theta, seq[-1].estimate / target)
            marked = np.flatnonzero(dorfler(cells, fraction, self.comm))
            if mesh.dim == 2 and seq[-1].estimate > CORNER_RATIO * target:
                corners = np.flatnonzero(dorfler(cells, CORNER_THETA, self.comm))
                if self.comm.allreduce(len(corners), op=MPI.SUM) <= SMALL_SET * mesh.num_cells():
                    return refine_twice(mesh, marked, corners)
            if mesh.dim == 2 and self.comm.allreduce(len(marked), op=MPI.SUM) <= SMALL_SET * mesh.num_cells():
                return refine_twice(mesh, marked)
            return refine(mesh, marked)

        if marked is not None:
            if solved_first and retarget is not None:
                new = retarget(seq[-1], seq[-1].estimate <= target)
                target = target if new is None else new
                if seq[-1].estimate <= target:
                    return marked
            round_started = time.perf_counter()  # after retarget, whose calibration and zeta runs count apart
            geo = refined(*marked)
        else:
            round_started = time.perf_counter()
        solved = 0
        while True:
            lv = probe.solve(degree, self.comm, geo, self.models.get(degree))
            self.models[degree] = lv.model
            self._keep_start(probe, degree, lv)
            rec = MeshRecord(degree, lv.model.geo.num_cells(), lv.dofs, lv.indicator, self.C[degree] * lv.indicator,
                             geo=lv.model.geo, seconds=time.perf_counter() - round_started)
            seq.append(rec)
            solved += 1
            self.log(f"  P{degree}: {rec.cells} cells, {rec.dofs} dofs, C eta = {rec.estimate:.3e} "
                     f"(target {target:.3e})")
            if retarget is not None:
                new = retarget(rec, rec.estimate <= target)
                target = target if new is None else new
            if rec.estimate <= target or (max_steps is not None and solved >= max_steps) or \
                    (accept is not None and accept(rec)):
                return lv.model.geo, lv.cell_indicators
            if rec.dofs > self.setup.max_dofs:
                raise ToleranceError(self.setup.tol, rec.estimate, rec.dofs, self.setup.limit, target=target)
            round_started = time.perf_counter()
            geo = refined(lv.model.geo, lv.cell_indicators)


def plan(scene: Config, comm: MPI.Comm, log: Log = print) -> Plan:
    """Choose degree, mesh and step for the scene's ``accuracy.tolerance`` (collective): ``scene`` is a Config,
    and the run's is ``plan(...).config``."""
    return Planner(prepare(scene, comm, log), comm, log).plan()
