"""The failure types: fields, composed messages, and and the one-word kind of each failure."""

import pytest

from solver.errors import (
    ConfigError,
    DamageSolveError,
    DisplacementSolveError,
    InputError,
    NonFiniteError,
    SolveFailure,
    UsageError,
)

pytestmark = pytest.mark.serial  # no MPI here: on 2 ranks each would run the same checks again


def test_config_error_composes_its_message_from_fields():
    err = ConfigError(source="s.toml", key="mesh.nx", value=0, allowed="must be at least 1")
    assert str(err) == "s.toml: mesh.nx = 0: must be at least 1"
    assert (err.key, err.value, err.allowed) == ("mesh.nx", 0, "must be at least 1")
    assert str(ConfigError(key="time.k", value="x", allowed="must be a number")) == "time.k = 'x': must be a number"
    assert isinstance(err, InputError) and isinstance(UsageError("u"), InputError)


def test_a_failure_learns_where_it_happened():
    err = DisplacementSolveError("SNES", "DIVERGED_MAX_IT", 4, [1.0, 0.5, 0.25], 1e-10, linear_reason=-3)
    assert err.step is None and "step" not in str(err)
    assert err.at(7, 0.35) is err
    assert (err.step, err.t) == (7, 0.35)
    assert str(err).startswith("step 7, t = 0.35: displacement solve failed: SNES DIVERGED_MAX_IT, linear solve -3")
    assert err.residuals == [1.0, 0.5, 0.25] and err.tolerance == 1e-10
    assert str(err.args[0]) == str(err)  # what an uncaught traceback would print


@pytest.mark.parametrize("reason,kind", [
    ("DIVERGED_RESIDUAL_GROWTH", "diverged"), ("DIVERGED_FNORM_NAN", "diverged"),
    ("DIVERGED_STAGNATION", "stagnated"), ("DIVERGED_MAX_IT", "too_many_iterations"),
    ("DIVERGED_LINEAR_SOLVE", "failed"),
])
def test_the_kind_follows_the_reason_field(reason, kind):
    assert DisplacementSolveError("newton", reason, 1, [1.0], 1.0).kind == kind


def test_other_failures_have_their_own_kind():
    assert DamageSolveError("DIVERGED_ITS").kind == "damage_failed"
    nf = NonFiniteError(["memory", "displacement", "memory"])
    assert nf.fields == ["displacement", "memory"] and nf.kind == "non_finite"
    assert all(isinstance(e, SolveFailure) for e in (nf, DamageSolveError("x")))
