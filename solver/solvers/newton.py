"""Semismooth Newton on a level's displacement problem, driven by PETSc SNES (docs/model.md §3.3, §4).

The contact term's generalized derivative is H(u_nu - g)/mu (UFL differentiates max_value to
it). The Jacobian is rebuilt only when the active set changes, and PETSc refactors a
matrix only when it was modified, so a step with an unchanged active set costs one
triangular solve pair (with ``solver.linear = "iterative"``, GAMG is likewise set up again only
then; see :func:`linear.iterative_options`). Without contact (and without an implicit memory term) the problem
is linear and SNES runs as a single KSP solve.

The parts: :class:`NewtonTest` (when to stop), :class:`~cycle_watch.ActiveSetCycleWatch` (a revisited active
set), :class:`~damped_newton.DampedFallback` (a failed level handed to damped Newton),
:class:`~linear.KrylovTolerance` (how far a Newton step's Krylov solve goes), :func:`make_snes` (the wiring);
:class:`NewtonCore` is what every Newton-type method shares on one problem (the SNES, its KSP, the Jacobian
callbacks, the counters, a level's outcome); :class:`NewtonSolver` runs a level through them.
"""

from __future__ import annotations

import logging
from collections.abc import Callable
from dataclasses import replace

import numpy as np
from dolfinx.fem import petsc as fpetsc
from mpi4py import MPI
from petsc4py import PETSc

from solver.errors import DisplacementSolveError
from solver.physics.contact import ContactTerm
from solver.physics.displacement import DisplacementProblem, SolveInfo
from solver.solvers.continuation import FIRST_STEPS, STAGE_ITERATIONS, ComplianceContinuation, ZoneShrinks
from solver.solvers.cycle_watch import CONVERGED_SET, CYCLE, DIVERGED_CYCLE, ActiveSetCycleWatch
from solver.solvers.damped_newton import DampedFallback, has_energy
from solver.solvers.linear import (
    REASONS_KSP,
    REASONS_SNES,
    KrylovTolerance,
    OwnOptions,
    check_options,
    direct_options,
    linear_options,
    rigid_body_modes,
)
from solver.solvers.method import DisplacementMethod
from solver.solvers.settings import LinearSettings, NewtonSettings

# a node of Gamma_C holds u . n (its normal leaves the near-nullspace) where the contact's stiffness (1/mu) int phi ds
# is this many times K's diagonal there; where the contact is soft, taking the normal out costs Krylov iterations
# (docs/benchmarks/performance.md, "Krylov iterations and the contact stiffness")
STIFF_CONTACT_RATIO = 100.0
# a kept active set ends a level where ||F|| is at most this many times the contact term's round-off, eps times
# the norm of its summands (1/mu)(|u_nu| + |g|) phi n at the penetrating points (ContactTerm.roundoff): on
# configs/moving_contact.toml the residual after the steps through K was 0.07-4.5 times that (median 0.16) and a
# further step did not lower it; on column3d.toml's first level one direct solve left 1.9e-9 (100 rtol * scale
# accepted it), where the next step reached 1e-15 and moved the contact pressure by 7e-8 relative (docs/model.md §4)
SET_FLOOR = 10.0
# after a failed iterative linear solve put the core on the direct solver (NewtonCore.use_direct), the levels it
# solves there before the iterative solver has the next one again; None: the rest of the run. None: going back
# after 1 level was 1.06 times as slow on the 3-D sphere (27,537 dofs), whose next level failed GAMG again
# (docs/model.md §4)
DIRECT_LEVELS: int | None = None

log = logging.getLogger("solver")


def contact_normals(problem: DisplacementProblem) -> np.ndarray:
    """The unit normal (nodes, d; ghosts included) at the nodes of Gamma_C where the contact is stiff against K
    (:data:`STIFF_CONTACT_RATIO`), zero elsewhere: the nodes whose normal motion linear.rigid_body_modes takes out."""
    N, diag = problem.ops.b.duplicate(), problem.ops.b.duplicate()
    problem.contact.normal_stiffness(N)
    problem.ops.K.getDiagonal(diag)
    diag.ghostUpdate(addv=PETSc.InsertMode.INSERT, mode=PETSc.ScatterMode.FORWARD)
    bs = problem.u.function_space.dofmap.index_map_bs
    with N.localForm() as n_local, diag.localForm() as d_local:
        n = n_local.array.reshape(-1, bs).copy()
        k = np.abs(d_local.array.reshape(-1, bs)).mean(axis=1)
    N.destroy()
    diag.destroy()
    stiffness = np.linalg.norm(n, axis=1)
    stiff = stiffness > STIFF_CONTACT_RATIO * k
    n[~stiff] = 0.0
    n[stiff] /= stiffness[stiff, None]
    return n


class NewtonTest:
    """The project's convergence test: ||F|| <= rtol * scale, or ||du|| <= rtol ||u|| after a Newton step.

    With 1/mu ~ 1e10 the residual has a round-off floor ~ eps ||J|| ||u|| that can exceed rtol * scale; a
    correction below rtol ||u|| then means the active set is settled and the direct solve exact. While the
    cycle watch is watching, an iterate whose active set is revisited stops the level (DIVERGED_CYCLE) instead
    of running on to max_it. While ``exact_steps`` is set (plain Newton's full steps, solved by a direct solver, on
    a piecewise linear law without implicit memory term), an iterate that keeps the active set its step was solved
    on stops the level (CONVERGED_SET) where ||F|| is within SET_FLOOR of its round-off: the step solved that set's
    linear equations, so the iterate is the level's solution to round-off, whose floor (~ eps ||J|| ||u||, with 1/mu
    ~ 1e10) may lie above rtol * scale; the step test would stop it one step later, on a step below rtol ||u||.
    """

    def __init__(self, rtol: float, max_it: int, cycles: ActiveSetCycleWatch, contact: ContactTerm | None) -> None:
        self.rtol, self.max_it, self.cycles, self.contact = rtol, max_it, cycles, contact
        self.scale = 1.0  # the level's force scale (:meth:`start_level`)
        # where set (auto's Newton, which has a take-over): a run of this many iterations each raising ||F|| stops
        # the solve (DIVERGED_DTOL); None: no such test
        self.growth_limit: int | None = None
        self.exact_steps = False  # set by NewtonCore.plain_newton where a kept active set ends the level
        # where set (a first contact's plain steps: continuation.ZoneShrinks): a test of the iteration number that
        # stops the solve (DIVERGED_MAX_IT) where it is true; None: no such test
        self.stop_early: Callable[[int], bool] | None = None
        self._last, self._grown = np.inf, 0

    def start_level(self, scale: float) -> None:
        """A new level, whose force scale is ``scale`` (||F|| <= rtol * scale)."""
        self.scale = scale

    def near_floor(self, fnorm: float) -> bool:
        """Whether ||F|| is within SET_FLOOR of the contact term's round-off at the current u
        (:meth:`ContactTerm.roundoff`): where a kept active set may end the level. Collective."""
        return fnorm <= SET_FLOOR * self.contact.roundoff()

    def __call__(self, it: int, xnorm: float, snorm: float, fnorm: float) -> int:
        """The SNES reason after iteration ``it`` (ITERATING to go on)."""
        rtol = self.rtol
        R = PETSc.SNES.ConvergedReason
        if not np.isfinite(fnorm):
            return R.DIVERGED_FNORM_NAN
        if fnorm <= rtol * self.scale:
            return R.CONVERGED_FNORM_ABS
        if it > 0 and snorm <= rtol * xnorm:
            return R.CONVERGED_SNORM_RELATIVE
        key = self.contact.active_set_at() if it > 0 and (self.exact_steps or self.cycles.watching) else None
        if self.exact_steps and key is not None and self.near_floor(fnorm) and self.contact.comm.allreduce(
                key == self.contact.fingerprint(), op=MPI.LAND):
            return CONVERGED_SET
        if it >= self.max_it or (self.stop_early is not None and self.stop_early(it)):
            return R.DIVERGED_MAX_IT
        self._grown = self._grown + 1 if (it > 0 and fnorm > self._last) else 0
        self._last = fnorm
        if self.growth_limit is not None and self._grown >= self.growth_limit:
            return R.DIVERGED_DTOL
        if self.cycles.watching and key is not None and self.cycles.revisited(key):
            return DIVERGED_CYCLE
        return R.ITERATING


def newton_options(comm: MPI.Comm, problem: DisplacementProblem, linear: LinearSettings,
                   rtol: float) -> dict[str, str]:
    """The SNES's default options (without prefix): the linear solver's (its Krylov tolerance from Newton's
    ``rtol``), and Newton's."""
    options = linear_options(comm, linear.kind, problem.symmetric, rtol, elasticity=True)
    options.update({
        "snes_type": "newtonls" if problem.nonlinear else "ksponly",
        "snes_linesearch_type": "basic",
        # the penalty 1/mu makes the residual jump by ~1/mu when contact first activates:
        # not a divergence, so PETSc's residual-growth test is off (max_it still applies)
        "snes_divergence_tolerance": "-1",
    })
    return options


def make_snes(comm: MPI.Comm, prefix: str, problem: DisplacementProblem, settings: NewtonSettings,
              residual: Callable, jacobian: Callable, test: NewtonTest) -> PETSc.SNES:
    """A SNES on ``problem`` with the callbacks and the test, reading its options under ``prefix`` (already in
    PETSc's database)."""
    snes = PETSc.SNES().create(comm)
    snes.setOptionsPrefix(prefix)
    snes.setFunction(residual, problem.r.duplicate())
    snes.setJacobian(jacobian, problem.J, problem.J)
    snes.setTolerances(rtol=settings.rtol, atol=0.0, stol=settings.rtol, max_it=settings.max_it)
    snes.setConvergenceTest(lambda _snes, it, norms: test(it, *norms))
    snes.setConvergenceHistory(reset=True)
    snes.setFromOptions()
    return snes


class NewtonCore:
    """What the Newton-type methods on one :class:`DisplacementProblem` share: the SNES (the scene's options under
    ``mech_``) with its KSP on J, the callbacks that count factorizations and record the level's first active set,
    the cycle watch, the Krylov tolerance policy, the counters of the run, and :meth:`outcome` (a level's
    SolveInfo or DisplacementSolveError). ``test`` is the SNES's (plain Newton's) convergence test."""

    prefix = "mech_"  # the scene's name for this solver's options

    def __init__(self, problem: DisplacementProblem, settings: NewtonSettings, linear: LinearSettings,
                 comm: MPI.Comm, test_max_it: int | None = None) -> None:
        self.problem, self.settings = problem, settings
        self.factorizations = 0  # factorizations (direct) or preconditioner set-ups (iterative)
        self.krylov_iterations = 0  # summed over the run (iterative solves)
        self.direct_switches = 0  # times :meth:`use_direct` has replaced the iterative solver
        self.direct_levels = 0  # levels the direct solver has solved since it replaced the iterative one
        self._direct_ksp: PETSc.KSP | None = None  # the direct solver's KSP, made at the first switch
        self._iterative_ksp: PETSc.KSP | None = None  # the iterative one while the direct one solves
        self._krylov_applies = False
        self._initial: PETSc.Vec | None = None  # the first residual of a solve, computed before SNES starts
        self._F0 = problem.r.duplicate()
        self.iterative = linear.iterative
        self.switchable = linear.iterative  # whether :meth:`use_direct` can replace the linear solver
        contact = problem.contact
        self.cycles = ActiveSetCycleWatch(contact.comm if contact else comm,
                                          has_energy(problem) and contact.piecewise_linear)
        self.krylov_tolerance = KrylovTolerance(settings.rtol, self.iterative, self.prefix, linear.petsc_options)
        self.test = NewtonTest(settings.rtol, settings.max_it if test_max_it is None else test_max_it, self.cycles,
                               contact)
        self._nullspace: PETSc.NullSpace | None = None
        if self.iterative:
            # CG + AMG on J with the rigid motions as near-nullspace (their normal component taken out on Gamma_C,
            # where the contact penalty holds u . n: linear.rigid_body_modes)
            near = contact is not None and settings.contact_near_nullspace
            normals = contact_normals(problem) if near else None
            self._nullspace = rigid_body_modes(problem.u.function_space, normals)
            problem.J.setNearNullSpace(self._nullspace)
        defaults = newton_options(comm, problem, linear, settings.rtol)
        check_options(comm, self.prefix, defaults, linear.petsc_options, snes=True)
        self.options = OwnOptions(self, self.prefix, defaults, linear.petsc_options)
        self.snes = make_snes(comm, self.options.prefix, problem, settings, self._residual, self._jacobian, self.test)

    def use_direct(self) -> None:
        """From now on (until :meth:`use_iterative`; :meth:`begin_level` calls it after DIRECT_LEVELS levels), solve J
        by MUMPS's Cholesky (LU if J is not symmetric; the direct solver auto picks for a
        3-D run below linear.AUTO_ITERATIVE_DOFS_3D dofs) instead of the iterative solver: the SNES gets a new KSP
        with options of its own (the scene's ``mech_`` options are the iterative solver's and are not applied).
        What auto does where CG + GAMG fails on a stiff contact Jacobian (docs/model.md §4). Collective."""
        if not self.iterative:
            return
        if self._direct_ksp is None:
            comm = self.problem.u.function_space.mesh.comm
            ksp = PETSc.KSP().create(comm)
            # the options live with the core (not the Python wrapper of the KSP): MUMPS reads mat_mumps_* when it
            # factors
            self._direct_options = OwnOptions(self, self.prefix + "direct_",
                                              direct_options(comm, "mumps", self.problem.symmetric), ())
            ksp.setOptionsPrefix(self._direct_options.prefix)
            ksp.setOperators(self.problem.J, self.problem.J)
            ksp.setFromOptions()
            self._direct_ksp = ksp
        self._iterative_ksp = self.snes.getKSP()  # kept, with its options, for :meth:`use_iterative`
        self.snes.setKSP(self._direct_ksp)
        self.iterative = False
        self._krylov_applies, self.krylov_tolerance.applies = self.krylov_tolerance.applies, False
        self.direct_switches += 1
        self.direct_levels = 0

    def use_iterative(self) -> None:
        """Back to the iterative solver :meth:`use_direct` replaced (nothing where it did not). Collective."""
        if self._iterative_ksp is None or self.iterative:
            return
        self._iterative_ksp.setOperators(self.problem.J, self.problem.J)
        self.snes.setKSP(self._iterative_ksp)
        self.iterative = True
        self.krylov_tolerance.applies = self._krylov_applies

    @property
    def on_direct(self) -> bool:
        """Whether :meth:`use_direct` has replaced the iterative solver (and :meth:`use_iterative` not undone it)."""
        return self._iterative_ksp is not None and not self.iterative

    def begin_level(self) -> None:
        """A level begins: back to the iterative solver where the direct one has solved DIRECT_LEVELS levels
        since a failed Krylov solve put the core on it."""
        if self.on_direct and DIRECT_LEVELS is not None and self.direct_levels >= DIRECT_LEVELS:
            self.use_iterative()

    def solve_level(self, solve: Callable[[], SolveInfo], start: PETSc.Vec) -> SolveInfo:
        """``solve()`` (a method's level from u, which ``start`` holds), and where its iterative linear solve
        fails, the level again from ``start`` on the direct solver (:meth:`use_direct`), one line in the log
        saying so: what ``newton`` and ``newton_energy`` do where CG + GAMG fails on a stiff contact Jacobian."""
        self.begin_level()
        f0 = self.factorizations
        try:
            return solve()
        except DisplacementSolveError as exc:
            if exc.linear_reason >= 0 or not self.iterative:
                raise
            failed = exc
        log.info("the iterative linear solver failed (%s, Newton iteration %d): the level is solved again by "
                 "MUMPS's direct solver (%s)", REASONS_KSP.get(failed.linear_reason, failed.linear_reason),
                 failed.iterations, "for the rest of the run" if DIRECT_LEVELS is None else
                 f"the iterative one again after {DIRECT_LEVELS} level{'s' if DIRECT_LEVELS > 1 else ''}")
        self.use_direct()
        u = self.problem.u
        start.copy(u.vector)
        u.x.scatter_forward()
        info = solve()
        return replace(info, iterations=info.iterations + failed.iterations,
                       linear_solves=info.linear_solves + failed.iterations,
                       factorizations=self.factorizations - f0)

    def scalars(self) -> dict[str, float]:
        """What a checkpoint carries of the linear solver: whether the direct one solves (after a failed Krylov
        solve) and the levels it has solved since."""
        return {"direct": float(self.on_direct), "direct_levels": float(self.direct_levels)}

    def restore_scalars(self, scalars: dict[str, float]) -> None:
        """Take back :meth:`scalars`: a restarted run goes on with the linear solver the checkpointed one had."""
        if scalars.get("direct", 0.0) > 0:
            self.use_direct()
            self.direct_levels = int(scalars.get("direct_levels", 0))

    def count_factorizations(self, n: int) -> None:
        """Count ``n`` factorizations (set-ups) made by a method's own iteration on the core's KSP or beside it."""
        self.factorizations += n

    @property
    def ksp(self) -> PETSc.KSP:
        """The KSP on J (every Newton-type method's linear solver)."""
        return self.snes.getKSP()

    def _residual(self, snes: PETSc.SNES, x: PETSc.Vec, F: PETSc.Vec) -> None:
        if self._initial is not None:  # the first evaluation, at u_{n-1}: already known
            self._initial.copy(F)
            self._initial = None
            return
        if self.iterative:
            # a Krylov step leaves the prescribed dofs off their values by its own error (~1e-17 after a step
            # of ~1e-2); the contact term couples them into free rows with 1/mu ~ 1e10, a residual of ~1e-7
            # the Jacobian (prescribed columns removed) cannot see, so Newton would stall there. A direct
            # solve puts them exactly; here the iterate is put on them before it is evaluated.
            fpetsc.set_bc(x, self.problem.bcs)
        self.problem.evaluate(x, F)

    def _jacobian(self, snes: PETSc.SNES, x: PETSc.Vec, J: PETSc.Mat, P: PETSc.Mat) -> None:
        if self.problem.update_jacobian(x):
            self.factorizations += 1
        elif self.factorizations == 0:  # the first solve factors the fixed K
            self.factorizations = 1
        if self.cycles.watching and not self.cycles.started:  # the level's first iterate
            self.cycles.first(self.problem.contact.fingerprint())

    def carry_first_residual(self) -> None:
        """The level's first residual, F(u_{n-1}), from the carried one: the SNES's first evaluation."""
        self.problem.first_residual(self._F0)
        self._initial = self._F0

    def plain_newton(self) -> tuple[int, np.ndarray, int]:
        """SNES on the level from u; its reason, residual history and iterations."""
        u = self.problem.u
        self.cycles.start()
        self.test.exact_steps = self.cycles.enabled and not self.iterative
        try:
            self.snes.solve(None, u.vector)
        finally:
            self.cycles.stop()
            self.test.exact_steps = False
        self._initial = None
        u.x.scatter_forward()
        history, _ = self.snes.getConvergenceHistory()
        return self.snes.getConvergedReason(), history, self.snes.getIterationNumber()

    def outcome(self, reason: int, name: str, history, its: int, scale: float, factorizations: int,
                krylov: int) -> SolveInfo:
        """The level's SolveInfo, or the DisplacementSolveError naming why it failed. ``krylov``: the Krylov
        iterations of the level's solves outside the SNES (iterative solver only)."""
        problem, u = self.problem, self.problem.u
        if problem.nonlinear:
            residual = float(history[its]) if len(history) > its else float("nan")
        else:
            problem.evaluate(u.vector, problem.r)
            residual = problem.r.norm()
        ksp_reason = self.snes.getKSP().getConvergedReason()
        krylov = (self.snes.getLinearSolveIterations() + krylov) if self.iterative else 0
        self.krylov_iterations += krylov
        tol = self.settings.rtol * scale
        ok = reason > 0 and ksp_reason >= 0 and np.isfinite(residual)
        if ok and not problem.nonlinear:
            # one exact (direct) solve of a linear problem: the residual must meet the tolerance
            ok = residual <= tol
        problem.level_converged() if ok else problem.forget_level()
        if ok and self.on_direct:
            self.direct_levels += 1
        if not ok:
            raise DisplacementSolveError("SNES", name, its, list(history), tol, linear_reason=ksp_reason)
        return SolveInfo(max(its, 1), factorizations, residual, name, linear_solves=max(its, 1),
                         krylov_iterations=krylov)


class RetriesDirectly:
    """A method on a :class:`NewtonCore` whose level, where the iterative linear solve fails, is solved again from its
    start on the direct solver (:meth:`NewtonCore.solve_level`), unless ``retry_direct`` is off (auto's take-over:
    auto retries itself). The method's own level is ``_solve``; its ``core``, ``problem`` and ``retry_direct`` are
    set by it, ``_start`` (None) too."""

    core: NewtonCore
    retry_direct: bool
    _start: PETSc.Vec | None

    def _solve(self, scale: float) -> SolveInfo:
        raise NotImplementedError

    def solve(self, scale: float) -> SolveInfo:
        """Solve the level (u holds the previous level as initial guess); raise DisplacementSolveError."""
        if not (self.retry_direct and (self.core.iterative or self.core.on_direct)):
            return self._solve(scale)
        if self._start is None:
            self._start = self.problem.u.vector.duplicate()
        self.problem.u.vector.copy(self._start)
        return self.core.solve_level(lambda: self._solve(scale), self._start)

    def scalars(self) -> dict[str, float]:
        """The linear solver's switch (NewtonCore.scalars)."""
        return self.core.scalars() if self.retry_direct and self.core.switchable else {}

    def restore_scalars(self, scalars: dict[str, float]) -> None:
        if self.retry_direct:
            self.core.restore_scalars(scalars)


class NewtonSolver(RetriesDirectly, DisplacementMethod):
    """Semismooth Newton (:class:`NewtonCore`'s SNES) on a :class:`DisplacementProblem`, one level per
    :meth:`solve`; a level plain Newton fails goes to the damped fallback where ``fallback`` allows it."""

    def __init__(self, core: NewtonCore, fallback: bool) -> None:
        self.core, self.problem = core, core.problem
        self.fallback = DampedFallback(core.problem, fallback, core.settings.max_it)
        self.continuation = ComplianceContinuation(core.problem) if core.problem.contact is not None else None
        # the iterate the compliance path ended at on the last level solved (None: that level took no path): where
        # auto's take-over starts a first contact Newton has not solved (auto.py)
        self.path_end: PETSc.Vec | None = None
        self._path_end: PETSc.Vec | None = None  # path_end's vector, made at the first compliance path
        self.take_path = True  # False: a first contact Newton's FIRST_STEPS do not solve fails there (auto.py sets it)

        # a level whose iterative linear solve fails is solved again on the direct solver (NewtonCore.solve_level);
        # auto, which has its own retry, turns it off
        self.retry_direct = True
        self._start: PETSc.Vec | None = None

    @property
    def fallbacks(self) -> int:
        """Levels solved by the damped fallback."""
        return self.fallback.levels

    def _solve(self, scale: float) -> SolveInfo:
        core = self.core
        core.test.start_level(scale)
        core.krylov_tolerance.apply(core.ksp, scale)
        core.carry_first_residual()
        f0 = core.factorizations
        self.fallback.remember_start()
        self.path_end = None
        if self.continuation is not None and self.continuation.applies():
            reason, history, its = self._first_contact()
        else:
            reason, history, its = core.plain_newton()
        cycled = core.cycles.cycled
        if reason < 0 and self.fallback.allowed:
            cycled = False  # the fallback's own reason names its outcome
            reason, history, its, factorizations = self.fallback.take_over(
                core.ksp, core.test, list(history[:its + 1]), its, core.iterative)
            core.count_factorizations(factorizations)
        name = CYCLE if (cycled and reason < 0) else REASONS_SNES.get(reason, str(reason))
        return core.outcome(reason, name, history, its, scale, core.factorizations - f0,
                            self.fallback.krylov_iterations)

    def _first_contact(self) -> tuple[int, np.ndarray, int]:
        """A first contact: plain Newton for at most FIRST_STEPS iterations (DECIDE_STEPS where the zone shrinks and
        the path is to be taken: continuation.ZoneShrinks), and where that does not solve the level, the compliance
        path from where it stands (continuation.py): each stage at most STAGE_ITERATIONS steps from the last, then
        the level's own problem (s = 1) under the level's test. Returns the last run's reason, the residual history
        (each run's but its last, the last one's whole) and the iterations of all."""
        core, path = self.core, self.continuation
        test, limit = core.test, core.test.max_it
        R = PETSc.SNES.ConvergedReason
        test.max_it = min(FIRST_STEPS, limit)
        test.stop_early = ZoneShrinks(core.problem) if self.take_path else None
        try:
            reason, first, its = core.plain_newton()
        finally:
            test.max_it = limit
            test.stop_early = None
        if reason > 0 or reason not in (R.DIVERGED_MAX_IT, DIVERGED_CYCLE) or its >= limit or not self.take_path:
            return reason, first, its
        history = list(first[:its])
        try:
            for s in path.scales:
                path.set_scale(s)
                test.max_it = min(STAGE_ITERATIONS, limit)
                reason, stage, n = core.plain_newton()
                history.extend(stage[:n])
                its += n
                if reason < 0 and reason not in (R.DIVERGED_MAX_IT, DIVERGED_CYCLE):
                    break  # a failed solve: the level's own problem from here, as plain Newton would
        finally:
            test.max_it = limit
            path.set_scale(1.0)
        path.levels += 1
        if self._path_end is None:
            self._path_end = core.problem.u.vector.duplicate()
        core.problem.u.vector.copy(self._path_end)
        self.path_end = self._path_end
        reason, stage, n = core.plain_newton()
        history.extend(stage[:n + 1])
        return reason, np.asarray(history), its + n
