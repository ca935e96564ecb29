"""First contact by a continuation in the compliance (docs/model.md §4).

On a level whose active set starts empty (no contact force at its start), semismooth Newton's first step is the
solve without contact: the body moves onto the obstacle as if it were not there and penetrates it wherever the
displacement would. That zone is wider than the contact zone (by sqrt 2 in radius for Hertz's sphere), and from it
the stiff law's Newton shrinks the zone by about one contact point per iteration: the point at its edge is the only
one in tension, where a rigid punch held over the whole zone has its singular edge pressure. So the iterations grow
with the number of points between the two zones: 23 (P1, n = 200) and 42 (P2, n = 100) on Hertz line contact
(measured: docs/model.md §4).

The cure is a path in the compliance: the contact term s j(u) (the laws s p, as soft as mu / s) for s going up
geometrically to 1, each stage started from the last. Where the contact is soft against the body (its stiffness
(s / mu) int phi ds about K's diagonal) every point of the zone sees its own penetration and the zone moves by many
points a step; a stage of STAGE_ITERATIONS Newton steps is enough to carry the zone to the next, and at
RATIOS[-1] the zone is the stiff one's to within a point, so the last stage (s = 1, the level's own problem with the
method's own test and limit) takes one or two steps. The stages need not converge: they only bring the iterate
close; the level's solution is that of the last stage, the stiff law's, to the solver's tolerance.

A first contact that plain Newton settles at once (the shipped scenes' first levels: 3 iterations) needs no path,
which would cost it 4 more: plain Newton runs first for FIRST_STEPS iterations, and the path starts from where it
stands only where they did not solve the level. It starts after DECIDE_STEPS iterations already where the zone has
begun to shrink (:class:`ZoneShrinks`: fewer rows of C at the second iterate than at the first): that is the slow
mode the path is for (the zone of the solve without contact closing by a point a step), where the shipped scenes'
first levels keep their zone from the first iterate to the second and are settled by the third.

The stiffness ratio R is :func:`contact_stiffness_ratio` (the largest over Gamma_C's nodes); a stage's s is its ratio
over R. The path is taken with the linear law only (where it was measured): on Example 1's limited-penetration
foundation (a soft layer of 1e-7 on a stiff one) it took the first level from 6 iterations to 11. A contact already
soft (R <= STIFF) needs none.
"""

from __future__ import annotations

import numpy as np
from mpi4py import MPI
from petsc4py import PETSc

from solver.physics.displacement import DisplacementProblem

# the stages' contact stiffness against K's diagonal (each s = ratio / R < 1: the path is taken where R > STIFF)
RATIOS = (1.0, 10.0, 100.0)
FIRST_STEPS = 3  # plain Newton's iterations on a first contact before the path is taken (from where they end)
STAGE_ITERATIONS = 2  # Newton steps of a stage before s grows (its residual need not meet the tolerance)
DECIDE_STEPS = 2  # plain Newton's iterations after which a shrinking zone takes the path at once (ZoneShrinks)
STIFF = 10.0 * RATIOS[-1]  # a contact stiffer than this (ratio R) gets the path on a first contact


def contact_stiffness_ratio(problem: DisplacementProblem) -> float:
    """The largest over Gamma_C's nodes of the contact's stiffness (1/mu) int phi ds against K's mean diagonal
    there (0 where the laws have no fixed stiffness: power). Collective."""
    contact = problem.contact
    if contact is None:
        return 0.0
    N, diag = problem.ops.b.duplicate(), problem.ops.b.duplicate()
    contact.normal_stiffness(N)
    problem.ops.K.getDiagonal(diag)
    bs = problem.u.function_space.dofmap.index_map_bs
    n_own = N.getLocalSize() // bs
    n = N.array_r.reshape(-1, bs)[:n_own]
    k = np.abs(diag.array_r.reshape(-1, bs)[:n_own]).mean(axis=1)
    N.destroy()
    diag.destroy()
    stiffness = np.linalg.norm(n, axis=1)
    on = (stiffness > 0.0) & (k > 0.0)
    local = float((stiffness[on] / k[on]).max()) if on.any() else 0.0
    return contact.comm.allreduce(local, op=MPI.MAX)


class ComplianceContinuation:
    """The stages of a first contact (module docstring): which scales, and whether a level gets them."""

    def __init__(self, problem: DisplacementProblem) -> None:
        self.problem = problem
        self.ratio = contact_stiffness_ratio(problem)
        linear = problem.contact is not None and problem.contact.linear
        self.scales = tuple(r / self.ratio for r in RATIOS) if linear and self.ratio > STIFF else ()
        self.levels = 0  # levels solved through the path

    def applies(self) -> bool:
        """Whether the level about to be solved is a first contact of a stiff law: no contact force at its start
        (the last evaluation, at the level's start, found no point in contact)."""
        return bool(self.scales) and self.problem.contact_norm == 0.0

    def set_scale(self, s: float) -> None:
        """The contact term's factor (1: the level's own laws); the Jacobian is assembled anew."""
        contact = self.problem.contact
        contact.scale.value = PETSc.ScalarType(s)
        contact.forget()


def contact_rows(problem: DisplacementProblem) -> int:
    """The rows of the contact Jacobian C at the current u (the dofs next to a point in contact): the size of the
    contact zone, from C assembled there (ContactTerm.active_set_at: J and the recorded active set untouched).
    Collective."""
    contact = problem.contact
    contact.active_set_at()
    diag = contact.C.createVecLeft()
    contact.C.getDiagonal(diag)
    local = int(np.count_nonzero(diag.array_r))
    diag.destroy()
    return contact.comm.allreduce(local, op=MPI.SUM)


class ZoneShrinks:
    """Plain Newton's early stop on a first contact (module docstring), a test of the iteration number called by
    :class:`~newton.NewtonTest` at each iterate: True at iteration DECIDE_STEPS where C has fewer rows there than at
    the first iterate (the solve without contact). Collective."""

    def __init__(self, problem: DisplacementProblem) -> None:
        self.problem = problem
        self.rows: list[int] = []  # C's rows at the first iterates

    def __call__(self, it: int) -> bool:
        if it < 1 or it > DECIDE_STEPS:
            return False
        self.rows.append(contact_rows(self.problem))
        return it == DECIDE_STEPS and self.rows[-1] < self.rows[0]
