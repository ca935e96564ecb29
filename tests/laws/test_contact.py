"""The contact laws (solver/laws/contact.py), each checked by the same tests through the registry: a law added to
CONTACT_LAWS is checked here without a line of its own. Its UFL and numpy forms agree at random points of both
signs and next to its kinks, its slope is the UFL derivative and the finite difference, its kinks are where the
slope jumps, its inverse and resolvent invert it, and the scene validation of its keys names the key."""

import dataclasses

import numpy as np
import pytest
import ufl
from ufl.algorithms.apply_derivatives import apply_derivatives

from solver.config import LAWS, from_dict
from solver.config.boundary import to_toml
from solver.errors import ConfigError
from solver.laws.contact import CONTACT_LAWS, ContactLaw, PiecewiseLinearLaw, PointLaws

pytestmark = pytest.mark.serial  # no MPI in this layer: on 2 ranks each would run the same checks again

EPS = np.finfo(float).eps
LAW_CLASSES = list(CONTACT_LAWS.values())
_DOMAIN = ufl.Mesh(ufl.VectorElement("Lagrange", ufl.interval, 1))


def _scale(law: ContactLaw) -> float:
    """A length over which the law shows all its pieces."""
    return 2.0 * max((*law.kinks, 1e-2))


def _points(law: ContactLaw, n: int = 200) -> np.ndarray:
    """Random r of both signs, and r at, just below and just above every kink."""
    rng = np.random.default_rng(7)
    near = [k + d for k in (0.0, *law.kinks) for d in (0.0, -1e-300, 1e-300, -1e-9 * _scale(law), 1e-9 * _scale(law))]
    near += [k * f for k in law.kinks for f in (1 - 4 * EPS, 1 + 4 * EPS)]
    return np.concatenate([rng.uniform(-1.0, 1.0, n) * _scale(law), near])


def _ufl_at(expr_of, r: np.ndarray) -> np.ndarray:
    """expr_of(r) for a UFL symbol r, evaluated by UFL's own evaluator at each value of r."""
    c = ufl.Constant(_DOMAIN)
    expr = expr_of(ufl.variable(c))
    return np.array([float(expr((), {c: float(x)})) for x in r])


def _ufl_slope(law: ContactLaw, r: np.ndarray) -> np.ndarray:
    c = ufl.Constant(_DOMAIN)
    v = ufl.variable(c)
    expr = apply_derivatives(ufl.diff(law.ufl(v), v))
    return np.array([float(expr((), {c: float(x)})) for x in r])


def _off_kinks(law: ContactLaw, r: np.ndarray, h: float) -> np.ndarray:
    """The r at least h away from every kink (and from 0, where every law starts)."""
    return r[np.all([np.abs(r - k) > h for k in (0.0, *law.kinks)], axis=0)]


@pytest.fixture(params=LAW_CLASSES, ids=list(CONTACT_LAWS))
def law(request) -> ContactLaw:
    return request.param.example()


def test_registry_names_each_law_once():
    """Config's allowed law names are the registry's, and each entry is the class of that name."""
    assert LAWS == tuple(CONTACT_LAWS)
    assert all(cls.name == name for name, cls in CONTACT_LAWS.items())


def test_ufl_and_numpy_forms_agree(law):
    """p(r) of both forms to round-off: each is a few correctly rounded operations (max, /, * or pow, +) on
    non-negative terms, so they differ by at most 8 eps of p (pow's SIMD kernels are within a few ulp)."""
    r = _points(law)
    want, got = _ufl_at(law.ufl, r), law.pressure(r)
    assert np.all(np.abs(got - want) <= 8 * EPS * np.abs(want))
    assert np.all(got[r <= 0] == 0.0) and np.all(np.diff(law.pressure(np.sort(r))) >= 0.0)  # zero, then monotone


def test_slope_is_the_ufl_derivative_and_the_finite_difference(law):
    r = _points(law)
    h = 1e-6 * _scale(law)
    smooth = _off_kinks(law, r, 2 * h)
    want = _ufl_slope(law, smooth)
    assert np.all(np.abs(law.slope(smooth) - want) <= 8 * EPS * np.abs(want))
    fd = (law.pressure(smooth + h) - law.pressure(smooth - h)) / (2 * h)
    assert np.allclose(law.slope(smooth), fd, rtol=1e-6, atol=1e-9 * np.abs(want).max())


def test_kinks_are_where_the_slope_jumps(law):
    """At each kink the slope jumps up; between kinks (and beyond r = 0) it is continuous: no kink is missed."""
    h = 1e-9 * _scale(law)
    for k in law.kinks:
        below, above = law.slope(np.array([k - h, k + h]))
        assert above - below > 1e-3 * above
    below, above, far = law.slope(np.array([-h, h, _scale(law)]))
    assert (above - below > 1e-3 * far) == (0.0 in law.kinks)  # r = 0 is a kink where p' jumps there
    r = _off_kinks(law, _points(law), 1e-4 * _scale(law))
    r = r[r > 0]
    jump = law.slope(r + h) - law.slope(r - h)
    assert np.all(np.abs(jump) <= 1e-6 * law.slope(r))
    assert law.piecewise_linear == isinstance(law, PiecewiseLinearLaw)


def test_pieces_of_a_piecewise_linear_law(law):
    """p on each point's own piece is p, and its slope p': what the condensed solver's line search uses."""
    if not law.piecewise_linear:
        pytest.skip(f"{law.name} is not piecewise linear")
    r = _points(law)
    state = law.state(r)
    assert np.allclose(law.piece_pressure(r, state), law.pressure(r), rtol=8 * EPS, atol=0.0)
    assert np.array_equal(law.piece_slope(state), law.slope(r))
    assert law.kinks[0] == 0.0 and law.stiffness == law.ramps[0][1]


def test_resolvent_inverts_the_penalty_duality_map(law):
    """r from y = (1 - lam omega) r + lam p(r), lam omega = 1/2, omega = 1/mu (the penalty-duality solver's)."""
    if not law.piecewise_linear:
        pytest.skip(f"{law.name} has no closed-form resolvent")
    r = _points(law)
    omega = np.full_like(r, law.stiffness)
    lam = 1.0 / (2.0 * omega)
    y = (1 - lam * omega) * r + lam * law.pressure(r)
    assert np.allclose(law.resolvent(y, lam, omega), r, rtol=1e-12, atol=1e-13 * _scale(law))


def test_inverse_gives_the_penetration_of_a_pressure(law):
    r = np.abs(_points(law, 50)) + 1e-3 * _scale(law)
    for x, p in zip(r, law.pressure(r)):
        assert law.inverse(float(p)) == pytest.approx(x, rel=1e-12)


def _scene(contact: dict) -> dict:
    return {"boundary": {"left": {"role": "clamped"}, "bottom": {"role": "contact", **contact}}}


def test_config_builds_the_law_and_writes_it_back(law):
    """A scene's keys make the law object (BoundaryConfig.contact_law), and to_toml writes the same keys."""
    table = {"law": law.name, **law.parameters()}
    part = from_dict(_scene(table)).contact[0]
    assert part.contact_law == law and part.law == law.name
    assert {k: v for k, v in to_toml((part,))["bottom"].items() if k in table} == table


def test_validation_names_the_key(law):
    """Each key: a value that is no number, a negative one (every law's parameters are positive) and, for a key
    without a default, its absence are refused with a config error naming boundary.bottom.<key>."""
    table = {"law": law.name, **law.parameters()}
    optional = {f.name for f in dataclasses.fields(law) if f.default is not dataclasses.MISSING}
    for key in law.keys():
        for bad in ("x", -1.0, None):
            if bad is None and key in optional:
                continue
            data = {**table, key: bad} if bad is not None else {k: v for k, v in table.items() if k != key}
            with pytest.raises(ConfigError) as err:
                from_dict(_scene(data))
            assert err.value.key == f"boundary.bottom.{key}"
    other = next(k for cls in LAW_CLASSES for k in cls.keys() if k not in law.keys())
    with pytest.raises(ConfigError, match="not used by law") as err:
        from_dict(_scene({**table, other: 1.0}))
    assert err.value.key == f"boundary.bottom.{other}"


def test_point_laws_evaluate_each_run_with_its_law():
    """PointLaws over runs of all laws (as ContactPoints and the condensed solver hold them): each run's values
    are its law's, joined runs keep their order."""
    laws = [cls.example() for cls in LAW_CLASSES]
    parts = [PointLaws(((law, 7),)) for law in laws]
    joined = PointLaws.join([*parts, PointLaws(((laws[0], 0),))])
    r = np.concatenate([_points(law, 7)[:7] for law in laws])
    assert joined.size == r.size and joined.piecewise_linear == all(law.piecewise_linear for law in laws)
    for i, law in enumerate(laws):
        sl = slice(7 * i, 7 * i + 7)
        assert np.array_equal(joined.pressure(r)[sl], law.pressure(r[sl]))
        assert np.array_equal(joined.slope(r)[sl], law.slope(r[sl]))
        assert np.all(joined.column(lambda law: law.stiffness)[sl] == (law.stiffness or 0.0))
    linear = PointLaws.join(p for p, law in zip(parts, laws) if law.piecewise_linear)
    rl = np.concatenate([r[7 * i:7 * i + 7] for i, law in enumerate(laws) if law.piecewise_linear])
    assert np.array_equal(linear.piece_pressure(rl, linear.state(rl)), linear.pressure(rl))
    if not joined.piecewise_linear:
        with pytest.raises(TypeError):
            joined.state(r)


def test_power_law_of_exponent_one_has_the_linear_kink():
    """p = c r_+ jumps in slope at 0 like the linear law (m > 1: p' is continuous there, no kink)."""
    law = CONTACT_LAWS["power"](2.0, 1.0)
    assert law.kinks == (0.0,) and list(law.slope(np.array([-1e-9, 1e-9]))) == [0.0, 2.0]
    assert CONTACT_LAWS["power"](2.0, 1.5).kinks == ()
