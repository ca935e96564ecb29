"""solver/run/accuracy/__init__.py: the names the command line, the API, the studies and the tests import from
``solver.run.accuracy`` stay there."""

from solver.run import accuracy
from solver.run.accuracy import planner, sensor, zeta


def test_the_package_keeps_its_public_names():
    for name in ("plan", "Plan", "ErrorSensor", "contradicting", "degrees", "observed_exponent", "memory_dofs",
                 "dof_limit", "ZETA_EXPONENT_MIN", "ZETA_EXPONENT_MAX", "C_TIMES_2MU", "ADAPTED_RATE",
                 "COST_PER_DOF", "BYTES_PER_DOF", "CHOSEN_KEYS"):
        assert name in accuracy.__all__ and hasattr(accuracy, name), name
    assert accuracy.plan is planner.plan and accuracy.ErrorSensor is sensor.ErrorSensor
    assert accuracy.observed_exponent is zeta.observed_exponent and accuracy._theta is planner.dorfler_fraction
