"""solver/laws/damage.py: Fremond's source phi and its slope in zeta, UFL (the definition) against numpy at random
strains and damage values in 2-D and 3-D, against hand values, and the law's parameter checks."""

import numpy as np
import pytest
import ufl

from solver.config import DamageConfig, from_dict
from solver.errors import ConfigError
from solver.laws.damage import FremondSource, eta, psi

pytestmark = pytest.mark.serial  # no MPI in this layer: on 2 ranks each would run the same checks again

ULP = np.finfo(float).eps
# the same operations in the same order, but for eps : eps, which UFL and einsum may sum in another order
# (relative error <= d^2 u of the sum); the result's size bounds the rest
BOUND = 16 * ULP
LAW = FremondSource(lambda1=0.5, lambda2=10.0, lambda3=0.3, zeta_star=0.01, q_star=1.0)


def by_ufl(expr) -> float:
    """A scalar UFL expression of literals evaluated by UFL itself (no mesh, no compiler)."""
    return float(expr(()))


def sample(d: int, n: int, seed: int) -> tuple[np.ndarray, np.ndarray]:
    """Symmetric strains (n, d, d) around the cap q* (so that Psi's min acts both ways) and zeta on both sides of
    zeta*."""
    rng = np.random.default_rng(seed)
    a = rng.standard_normal((n, d, d)) * 10.0 ** rng.uniform(-2, 0.5, (n, 1, 1))
    zeta = np.concatenate([rng.uniform(0.0, 0.01, n // 4), rng.uniform(0.01, 1.0, n - n // 4)])
    return 0.5 * (a + a.transpose(0, 2, 1)), zeta


@pytest.mark.parametrize("d", [2, 3])
def test_the_ufl_and_numpy_forms_agree(d):
    eps, zeta = sample(d, 200, seed=d)
    fast = LAW.numpy(eps, zeta)
    ref = np.array([by_ufl(LAW.ufl(ufl.as_matrix(e.tolist()), z)) for e, z in zip(eps, zeta)])
    inner = np.einsum("nij,nij->n", eps, eps)
    assert np.any(inner > LAW.q_star) and np.any(0.5 * LAW.lambda2 * inner < LAW.lambda3)  # every branch taken
    scale = np.abs(ref) + LAW.lambda1 / LAW.zeta_star + 0.5 * LAW.lambda2 * LAW.q_star
    assert np.all(np.abs(fast - ref) <= BOUND * scale)


def test_the_slope_forms_agree():
    _, zeta = sample(2, 200, seed=5)
    zeta = np.append(zeta, LAW.zeta_star)  # at zeta* itself: the lower branch
    ref = np.array([by_ufl(LAW.ufl_slope(ufl.as_ufl(z))) for z in zeta])
    # lambda1 / zeta^2: numpy squares by a product, UFL's evaluation by pow (each correctly rounded or nearly)
    assert np.all(np.abs(LAW.slope(zeta) - ref) <= 4 * ULP * ref)
    assert LAW.slope(np.array([LAW.zeta_star]))[0] == 0.0 and np.all(ref[zeta > LAW.zeta_star] > 0)


def phi_hand(eps, z, c: FremondSource) -> float:
    e = z if z > c.zeta_star else c.zeta_star
    q = min(float(np.sum(eps * eps)), c.q_star)
    return -c.lambda1 * (1 - e) / e - max(0.5 * c.lambda2 * q - c.lambda3, 0.0)


@pytest.mark.parametrize("z", [1.0, 0.5, 0.02, 0.01, 0.005])
@pytest.mark.parametrize("scale", [0.0, 0.1, 2.0])
def test_source_hand_values(z, scale):
    c = DamageConfig(lambda3=0.3).law
    eps = scale * np.array([[0.3, 0.1], [0.1, -0.2]])
    got = by_ufl(c.ufl(ufl.as_matrix(eps.tolist()), ufl.as_ufl(z)))
    assert got == pytest.approx(phi_hand(eps, z, c), rel=1e-13, abs=1e-15)


def test_eta_and_psi():
    assert by_ufl(eta(ufl.as_ufl(0.3), 0.01)) == 0.3
    assert by_ufl(eta(ufl.as_ufl(0.001), 0.01)) == 0.01
    eps = ufl.as_matrix([[1.0, 2.0], [2.0, 3.0]])  # eps.eps = 18
    assert by_ufl(psi(eps, 20.0)) == pytest.approx(18.0)
    assert by_ufl(psi(eps, 1.0)) == 1.0


def test_the_config_carries_the_law():
    cfg = DamageConfig(lambda1=0.2, lambda2=3.0, lambda3=0.1, zeta_star=0.05, q_star=2.0)
    assert cfg.law == FremondSource(0.2, 3.0, 0.1, 0.05, 2.0)


@pytest.mark.parametrize("key,value,allowed", [("zeta_star", 0.0, "must be in (0, 1)"),
                                               ("zeta_star", 1.0, "must be in (0, 1)"),
                                               ("q_star", 0.0, "must be > 0"), ("lambda1", -1.0, "must be >= 0"),
                                               ("lambda2", -1.0, "must be >= 0"), ("lambda3", -0.1, "must be >= 0")])
def test_the_law_checks_its_parameters_and_the_scene_names_the_key(key, value, allowed):
    with pytest.raises(ConfigError) as err:
        FremondSource(**{key: value})
    assert (err.value.key, err.value.value, err.value.allowed) == (key, value, allowed)
    with pytest.raises(ConfigError) as err:
        from_dict({"damage": {key: value}})
    assert (err.value.key, err.value.value, err.value.allowed) == (f"damage.{key}", value, allowed)
