"""The parts of the semismooth Newton solver (solver/solvers/newton.py): the cycle watch, the convergence
test, the Krylov tolerance policy, the damped fallback's decision and the per-object PETSc options."""

import gc
from types import SimpleNamespace

import numpy as np
import pytest
from mpi4py import MPI
from petsc4py import PETSc

from solver.solvers.cycle_watch import DIVERGED_CYCLE, ActiveSetCycleWatch
from solver.solvers.damped_newton import FALLBACK_IT_FACTOR, DampedFallback
from solver.solvers.linear import KSP_RTOL_FACTOR, KrylovTolerance, OwnOptions
from solver.solvers.newton import NewtonTest

R = PETSc.SNES.ConvergedReason


def _revisits(keys, comm=MPI.COMM_SELF):
    """The watch's answers on a level whose iterates have the active sets ``keys`` (the first one recorded)."""
    watch = ActiveSetCycleWatch(comm, enabled=True)
    watch.start()
    watch.first(keys[0])
    return [watch.revisited(k) for k in keys[1:]], watch


@pytest.mark.parametrize("keys,answers", [
    (b"ab", [False]),
    (b"aa", [False]),  # the same set as the last iterate: Newton has settled, not cycled
    (b"aba", [False, True]),
    (b"abb", [False, False]),
    (b"abbca", [False, False, False, True]),
    (b"abcb", [False, False, True]),
])
def test_the_watch_names_a_set_met_again_other_than_the_last(keys, answers):
    said, watch = _revisits([bytes([k]) for k in keys])
    assert said == answers
    assert watch.cycled == any(answers)


def test_a_new_level_forgets_the_last_one_and_a_disabled_watch_does_not_watch():
    _, watch = _revisits([b"a", b"b", b"a"])
    assert watch.cycled
    watch.start()
    assert watch.watching and not watch.cycled and not watch.started
    watch.first(b"b")
    assert not watch.revisited(b"a")  # a was the last level's
    watch.stop()
    assert not watch.watching
    blind = ActiveSetCycleWatch(MPI.COMM_SELF, enabled=False)
    blind.start()
    assert not blind.watching


def test_a_set_is_met_again_only_when_it_is_on_every_rank(comm):
    """Collective: each rank holds its own part of the fingerprint."""
    key = b"mine" if comm.rank == 0 else b"other"
    said, _ = _revisits([key, b"x", key if comm.rank == 0 else b"y"], comm)
    assert said == [False, comm.size == 1]


def _test(cycles=None, contact=None):
    test = NewtonTest(1e-6, 5, cycles or ActiveSetCycleWatch(MPI.COMM_SELF, enabled=False), contact)
    test.start_level(10.0)
    return test


def test_the_convergence_test_in_its_order():
    test = _test()
    assert test(0, 1.0, 0.0, float("nan")) == R.DIVERGED_FNORM_NAN
    assert test(0, 1.0, 0.0, 0.9e-5) == R.CONVERGED_FNORM_ABS  # <= rtol * scale
    assert test(0, 1.0, 0.0, 2e-5) == R.ITERATING  # the step test needs a step
    assert test(1, 1.0, 1e-7, 2e-5) == R.CONVERGED_SNORM_RELATIVE
    assert test(5, 1.0, 1.0, 2e-5) == R.DIVERGED_MAX_IT
    assert test(4, 1.0, 1.0, 2e-5) == R.ITERATING


def test_the_convergence_test_stops_a_cycle_while_the_watch_watches():
    keys = iter([b"b", b"a"])
    contact = SimpleNamespace(active_set_at=lambda: next(keys))
    cycles = ActiveSetCycleWatch(MPI.COMM_SELF, enabled=True)
    test = _test(cycles, contact)
    cycles.start()
    cycles.first(b"a")
    assert test(0, 1.0, 1.0, 1.0) == R.ITERATING  # the first iterate is not asked again
    assert test(1, 1.0, 1.0, 1.0) == R.ITERATING
    assert test(2, 1.0, 1.0, 1.0) == DIVERGED_CYCLE < 0
    cycles.stop()
    assert test(3, 1.0, 1.0, 1.0) == R.ITERATING  # not watching: the active set is not even looked at


def test_krylov_tolerance_only_for_an_iterative_solver_the_scene_leaves_alone():
    policy = KrylovTolerance(1e-6, True, "mech_", (("mech_pc_type", "gamg"),))
    assert policy.applies
    assert policy.tolerances(10.0) == {"rtol": KSP_RTOL_FACTOR * 1e-6, "atol": KSP_RTOL_FACTOR * 1e-6 * 10.0}
    assert not KrylovTolerance(1e-6, False, "mech_", ()).applies
    assert not KrylovTolerance(1e-6, True, "mech_", (("-mech_ksp_rtol", "1e-3"),)).applies
    assert not KrylovTolerance(1e-6, True, "mech_", (("mech_ksp_atol", "0"),)).applies
    assert KrylovTolerance(1e-6, True, "mech_", (("damage_ksp_rtol", "1e-3"),)).applies
    ksp = PETSc.KSP().create(MPI.COMM_SELF)
    policy.apply(ksp, 10.0)
    assert ksp.getTolerances()[:2] == pytest.approx((1e-7, 1e-6))
    KrylovTolerance(1e-6, False, "mech_", ()).apply(ksp, 1e3)
    assert ksp.getTolerances()[:2] == pytest.approx((1e-7, 1e-6))  # left as it was
    ksp.destroy()


def _problem(contact, memory):
    """A problem with a contact term or not, and with the implicit memory term (which removes the split) or not."""
    vec = PETSc.Vec().createSeq(3, comm=MPI.COMM_SELF)
    split = None if memory is not None else object()
    return SimpleNamespace(contact=contact, Fm=memory, split=split, u=SimpleNamespace(vector=vec))


@pytest.mark.parametrize("scene,contact,memory,allowed", [
    (True, object(), None, True),
    (False, object(), None, False),  # the scene turned it off
    (True, None, None, False),  # no contact: no energy to descend (and a linear problem)
    (True, object(), object(), False),  # the implicit memory term: no energy
])
def test_the_fallback_is_allowed_only_with_an_energy_and_the_scenes_consent(scene, contact, memory, allowed):
    fallback = DampedFallback(_problem(contact, memory), scene, max_it=7)
    assert fallback.allowed == allowed and fallback.cap == FALLBACK_IT_FACTOR * 7


def test_own_options_under_a_prefix_of_each_object_gone_with_it():
    opts = PETSc.Options()
    class Owner:
        pass

    a, b = Owner(), Owner()
    user = (("t_pc_type", "jacobi"), ("-t_ksp_max_it", "3"), ("other_x", "1"))
    oa = OwnOptions(a, "t_", {"ksp_type": "cg", "pc_type": "lu"}, user)
    ob = OwnOptions(b, "t_", {"ksp_type": "gmres"}, ())
    assert oa.prefix != ob.prefix and oa.prefix.startswith("t_")
    pa, pb = oa.prefix, ob.prefix
    assert opts[f"{pa}ksp_type"] == "cg" and opts[f"{pa}pc_type"] == "jacobi" and opts[f"{pa}ksp_max_it"] == "3"
    assert opts[f"{pb}ksp_type"] == "gmres" and not opts.hasName(f"{pb}pc_type")
    assert not opts.hasName("t_pc_type") and not opts.hasName("other_x") and not opts.hasName(f"{pa}other_x")
    oa.remove(defaults_only=True)
    assert not opts.hasName(f"{pa}ksp_type") and opts[f"{pa}pc_type"] == "jacobi"  # the scene's stay
    del a, oa
    gc.collect()
    assert not opts.hasName(f"{pa}pc_type") and not opts.hasName(f"{pa}ksp_max_it")
    assert opts.hasName(f"{pb}ksp_type")
    ob.remove()
    assert not opts.hasName(f"{pb}ksp_type")


def test_a_ksp_reads_its_own_options_only():
    """Two solvers under one scene prefix with different options: each reads its own."""
    from solver.solvers.linear import make_ksp

    A = PETSc.Mat().createAIJ([2, 2], nnz=1, comm=MPI.COMM_SELF)
    A.setValue(0, 0, 2.0)
    A.setValue(1, 1, 4.0)
    A.assemble()
    one = make_ksp(MPI.COMM_SELF, A, "t_", (("t_ksp_type", "cg"),), "iterative")
    two = make_ksp(MPI.COMM_SELF, A, "t_", (), "iterative")
    assert one.getType() == "cg" and two.getType() == "cg"  # the default for a symmetric matrix
    three = make_ksp(MPI.COMM_SELF, A, "t_", (("t_ksp_type", "gmres"),), "iterative")
    assert three.getType() == "gmres" and one.getType() == "cg"
    x, b = A.createVecs()
    b.set(1.0)
    three.solve(b, x)
    assert np.allclose(x.array, [0.5, 0.25])
    for obj in (one, two, three, A, x, b):
        obj.destroy()


def test_a_kept_active_set_ends_the_level_near_the_floor_and_only_with_exact_steps():
    """CONVERGED_SET where the step's end keeps the set it was solved on (the fingerprint of the last Jacobian),
    ||F|| within SET_FLOOR of the contact term's round-off and exact_steps set (plain Newton, direct solve); not
    otherwise, whatever rtol * scale is."""
    from solver.solvers.cycle_watch import CONVERGED_SET
    from solver.solvers.newton import SET_FLOOR

    now = {"key": b"a"}
    contact = SimpleNamespace(active_set_at=lambda: now["key"], fingerprint=lambda: b"a", comm=MPI.COMM_SELF,
                              roundoff=lambda: 1e-3)  # rtol * scale = 1e-5 below it: the floor decides
    test = _test(None, contact)
    near, far = 0.5 * SET_FLOOR * 1e-3, 2.0 * SET_FLOOR * 1e-3
    assert test(1, 1.0, 1.0, near) == R.ITERATING  # exact_steps off: damped steps keep sets without solving
    test.exact_steps = True
    assert test(0, 1.0, 0.0, near) == R.ITERATING  # no step yet
    assert test(1, 1.0, 1.0, near) == CONVERGED_SET > 0
    assert test(1, 1.0, 1.0, far) == R.ITERATING  # above the round-off: another step
    now["key"] = b"b"
    assert test(1, 1.0, 1.0, near) == R.ITERATING  # the set moved
