"""The residual estimator: zero where the discrete solution is exact, the same on 2 ranks as on one,
a constant ratio to the true error under refinement (what the tolerance control relies on), and
Dörfler marking."""

import numpy as np
import pytest
from conftest import ROOT
from mpi4py import MPI

from solver.config import from_dict
from solver.physics.estimator import dorfler, estimator_for
from solver.run.model import build_model
from solver.run.stepper import Stepper
from studies.estimator import calibrate


def _level0(comm, scene: dict):
    model = build_model(from_dict(scene), comm)
    Stepper(model).step(0)
    return model


def test_zero_for_a_uniform_stress(comm):
    """A block on rollers pulled by a uniform traction: u is linear, so P1 is exact and every residual vanishes."""
    scene = {"mesh": {"nx": 4, "ny": 3, "corners": [[0, 0], [2, 1]]}, "material": {"E": 100.0, "nu": 0.3},
             "boundary": {"left": {"role": "displacement", "displacement": [0.0, "free"]},
                          "bottom": {"role": "displacement", "displacement": ["free", 0.0]},
                          "right": {"role": "traction", "traction": [10.0, 0.0]}},
             "memory": {"kernel": "none"}, "damage": {"enabled": False}, "time": {"T": 1.0, "k": 1.0}}
    model = _level0(comm, scene)
    eta = estimator_for(model).total()
    assert eta < 1e-12 * 10.0
    # a shear load on the same end bends the block: u is not linear, and the estimate sees it
    scene["boundary"]["right"]["traction"] = [10.0, 1.0]
    assert estimator_for(_level0(comm, scene)).total() > 1e-2


def test_parallel_equals_serial(comm):
    scene = {"mesh": {"nx": 8, "ny": 8}, "time": {"T": 1.0, "k": 1.0}}
    eta = estimator_for(_level0(comm, scene)).total()
    serial = estimator_for(_level0(MPI.COMM_SELF, scene)).total()
    assert eta == pytest.approx(serial, rel=1e-10)


@pytest.mark.serial
def test_ratio_to_the_true_error_is_steady_under_refinement():
    """Example 1 at t = 0 against a P2 solve on a nested finer mesh: error / eta moves by less than 10% from
    n = 8 to 32 (P1), and eta falls at the error's rate (within 0.15)."""
    result = calibrate(ROOT / "configs" / "example1.toml", [(1, 8), (1, 16), (1, 32)], ref_n=64, log=lambda s: None)
    runs = result["runs"]
    C = [r["C"] for r in runs]
    assert max(C) / min(C) < 1.1, C
    for r in runs[1:]:
        assert abs(r["rate_eta"] - r["rate_error"]) < 0.15, r


def test_dorfler_marks_the_fewest_largest_cells(comm):
    rng = np.random.default_rng(comm.rank)
    eta2 = rng.random(50) ** 4
    marked = dorfler(eta2, 0.5, comm)
    total = comm.allreduce(eta2.sum(), op=MPI.SUM)
    chosen = comm.allreduce(eta2[marked].sum(), op=MPI.SUM)
    assert chosen >= 0.5 * total
    # every marked cell is larger than every unmarked one, and without the smallest marked one theta is missed
    smallest = comm.allreduce(float(eta2[marked].min(initial=np.inf)), op=MPI.MIN)
    largest_left = comm.allreduce(float(eta2[~marked].max(initial=0.0)), op=MPI.MAX)
    assert smallest >= largest_left
    assert chosen - smallest < 0.5 * total
    assert not dorfler(np.zeros(3), 0.5, comm).any()


def _pressure(comm, degree: int, nx: int, uy):
    """Example 1's square (contact on the bottom, mu = 1e-3) with u = (0, uy(x)) put in, and its estimator's
    contact pressure lambda_h updated."""
    scene = {"mesh": {"nx": nx, "ny": nx}, "time": {"T": 1.0, "k": 1.0}, "discretization": {"u_degree": degree},
             "boundary": {"left": {"role": "clamped"}, "bottom": {"role": "contact", "gap": 0.0, "mu": 1e-3}},
             "memory": {"kernel": "none"}, "damage": {"enabled": False}}
    model = build_model(from_dict(scene), comm)
    model.u.interpolate(lambda x: np.stack([0.0 * x[0], uy(x[0])]))
    est = estimator_for(model)
    est.pressure.update()
    return model, est.pressure.pressure


@pytest.mark.parametrize("degree", [1, 2])
def test_the_contact_pressure_is_the_compliance_where_that_is_in_the_trace_space(comm, degree):
    """All of Γ_C pressed in by a u_nu of degree p: p(u_nu) = u_nu / mu is a trace of the space, and lambda_h,
    its projection with the contact rule (exact for p psi), is it; off Γ_C lambda_h is zero."""
    def uy(x):
        return -(0.01 + 0.02 * x + (0.03 * x**2 if degree == 2 else 0.0))

    model, lam = _pressure(comm, degree, 4, uy)
    x = lam.function_space.tabulate_dof_coordinates()
    bottom = np.isclose(x[:, 1], 0.0)
    assert np.allclose(lam.x.array[bottom], -uy(x[bottom, 0]) / 1e-3, rtol=1e-10, atol=0.0)
    assert np.all(lam.x.array[~bottom] == 0.0)


def test_the_contact_pressure_carries_the_discrete_contact_force(comm):
    """With the edge of the contact zone inside a facet (u_nu > 0 for x > 0.5, 5 cells across), lambda_h differs
    from the pointwise p there, but its integral is the contact force the discrete equations carry: psi = 1 is
    a trace of the space."""
    from dolfinx import fem

    model, lam = _pressure(comm, 2, 5, lambda x: -(0.02 * x - 0.01))
    force = model.mech.diagnostics.contact_force()
    total = comm.allreduce(fem.assemble_scalar(fem.form(lam * model.geo.ds(model.geo.tags["bottom"]))), op=MPI.SUM)
    assert force > 0.0 and total == pytest.approx(force, rel=1e-10)
    x = lam.function_space.tabulate_dof_coordinates()
    bottom = np.isclose(x[:, 1], 0.0)
    pointwise = np.maximum(0.02 * x[bottom, 0] - 0.01, 0.0) / 1e-3  # the law at the nodes: not what lambda_h is
    assert np.abs(lam.x.array[bottom] - pointwise).max() > 1e-2 * pointwise.max()
