"""solver/run/accuracy/constants.py: every degree the scene may choose is calibrated."""

import pytest

from solver.config.discretization import DEGREES
from solver.run.accuracy.constants import (
    ADAPTED_RATE,
    ADAPTED_RATE_3D,
    C_TIMES_2MU,
    C_TIMES_2MU_3D,
    COST_PER_DOF,
    adapted_rate,
    c_times_2mu,
)


@pytest.mark.parametrize("table", [C_TIMES_2MU, ADAPTED_RATE, COST_PER_DOF, C_TIMES_2MU_3D, ADAPTED_RATE_3D])
def test_every_degree_has_a_positive_constant(table):
    assert set(table) == set(DEGREES) and all(v > 0 for v in table.values())


def test_the_estimators_constant_is_the_measured_one_on_example_1():
    """C = C_TIMES_2MU / (2 mu) on Example 1's material (E = 100, nu = 0.3, 2 mu = E / 1.3) is the rounded-up
    measurement of ``study estimator`` (docs/guide/accuracy.md)."""
    two_mu = 100.0 / 1.3
    assert C_TIMES_2MU[1] / two_mu == pytest.approx(4.0e-3, rel=1e-15)
    assert C_TIMES_2MU[2] / two_mu == pytest.approx(1.8e-3, rel=1e-15)


def test_higher_degrees_converge_faster_and_cost_more_per_dof():
    assert ADAPTED_RATE[2] > ADAPTED_RATE[1] and COST_PER_DOF[2] > COST_PER_DOF[1]


def test_tetrahedra_have_their_own_tables():
    """3-D: the estimator's constant measured below the 2-D one (kept); adapted meshes converge more slowly in dofs."""
    assert c_times_2mu(2) is C_TIMES_2MU and c_times_2mu(3) is C_TIMES_2MU_3D and C_TIMES_2MU_3D == C_TIMES_2MU
    assert adapted_rate(2) is ADAPTED_RATE and adapted_rate(3) is ADAPTED_RATE_3D
    assert all(ADAPTED_RATE_3D[d] < ADAPTED_RATE[d] for d in ADAPTED_RATE) and ADAPTED_RATE_3D[2] > ADAPTED_RATE_3D[1]
