"""solver/laws/memory.py: the memory integrand's UFL form (the definition) and its numpy form agree, in 2-D (plane
stress), plane strain (in-plane and H_33) and 3-D, with the truncation acting; and its parameter's check."""

import numpy as np
import pytest
import ufl

from solver.errors import ConfigError
from solver.laws.memory import MemoryIntegrand, pairs, truncate

pytestmark = pytest.mark.serial  # no MPI in this layer: on 2 ranks each would run the same checks again

E, NU = 100.0, 0.3
ULP = np.finfo(float).eps
# the two forms do the same operations up to the order of the commutative sum lambda tr(eps) + 2 mu eps_ij and
# zeta's product: a few roundings of the result's size apart
BOUND = 8 * ULP


def lame(model: str) -> tuple[float, float]:
    mu = E / (2 * (1 + NU))
    if model == "plane_stress":
        return E * NU / (1 - NU**2), mu
    return E * NU / ((1 + NU) * (1 - 2 * NU)), mu


def sample(d: int, n: int, seed: int) -> tuple[np.ndarray, np.ndarray]:
    """n random symmetric strains (n, d, d) spanning three decades, and damage values in [0.01, 1]."""
    rng = np.random.default_rng(seed)
    a = rng.standard_normal((n, d, d)) * 10.0 ** rng.uniform(-2, 1, (n, 1, 1))
    return 0.5 * (a + a.transpose(0, 2, 1)), rng.uniform(0.01, 1.0, n)


def by_ufl(expr) -> np.ndarray:
    """A UFL expression of literals evaluated by UFL itself (no mesh, no compiler)."""
    if expr.ufl_shape == ():
        return np.array(expr(()))
    return np.array([[expr[i, j](()) for j in range(expr.ufl_shape[1])] for i in range(expr.ufl_shape[0])])


def compact(eps: np.ndarray) -> np.ndarray:
    return np.array([eps[:, i, j] for i, j in pairs(eps.shape[-1])])


@pytest.mark.parametrize("model,d", [("plane_stress", 2), ("plane_strain", 2), ("3d", 3)])
def test_the_ufl_and_numpy_forms_agree(model, d):
    law = MemoryIntegrand(20.0, *lame(model))  # L well inside the stresses' range: the truncation acts
    eps, zeta = sample(d, 120, seed=d + len(model))
    fast = law.full(eps, zeta)
    ref = np.array([by_ufl(law.ufl(ufl.as_matrix(e.tolist()), z)) for e, z in zip(eps, zeta)])
    assert np.any(np.abs(ref) == law.L * zeta[:, None, None]) and np.any(np.abs(ref) < law.L * zeta[:, None, None])
    scale = np.abs(ref).max(axis=(1, 2), keepdims=True)
    assert np.all(np.abs(fast - ref) <= BOUND * scale)


def test_the_out_of_plane_forms_agree():
    """Plane strain's H_33 = zeta Phi_L(lambda tr eps): numpy from the compact components, UFL from the tensor."""
    law = MemoryIntegrand(20.0, *lame("plane_strain"))
    eps, zeta = sample(2, 120, seed=7)
    fast = law.out_of_plane(compact(eps), zeta)
    ref = np.array([float(by_ufl(law.ufl_out_of_plane(ufl.as_matrix(e.tolist()), z))) for e, z in zip(eps, zeta)])
    assert np.any(np.abs(ref) == law.L * zeta) and np.any(np.abs(ref) < law.L * zeta)
    assert np.all(np.abs(fast - ref) <= BOUND * np.abs(ref))


@pytest.mark.parametrize("d", [2, 3])
def test_compact_writes_its_buffer_and_scales(d):
    """The fast form writes the caller's buffer (no temporaries per step) and folds a scale into zeta's product."""
    law = MemoryIntegrand(1e30, *lame("3d" if d == 3 else "plane_stress"))
    eps, zeta = sample(d, 50, seed=11)
    c = compact(eps)
    out, trace = np.empty_like(c), np.empty(c.shape[1])
    got = law.compact(c, zeta, out, trace, scale=0.25)
    assert got is out
    plain = law.compact(c, zeta, np.empty_like(c), trace)
    assert np.all(np.abs(got - 0.25 * plain) <= BOUND * np.abs(plain))
    # no truncation below L: A eps itself, diagonal lambda tr + 2 mu eps_ii, off-diagonal 2 mu eps_ij
    lam, mu = law.lame_lambda, law.lame_mu
    tr = np.trace(eps, axis1=1, axis2=2)
    want = np.array([zeta * (lam * tr * (i == j) + 2 * mu * eps[:, i, j]) for i, j in pairs(d)])
    assert np.all(np.abs(plain - want) <= BOUND * np.abs(want).max(axis=0))


def test_truncate_is_componentwise():
    tau = ufl.as_matrix([[3.0, -5.0], [0.5, -1.0]])
    assert by_ufl(truncate(tau, 2.0)).tolist() == [[2.0, -2.0], [0.5, -1.0]]


@pytest.mark.parametrize("L", [0.0, -1.0, float("nan")])
def test_the_truncation_must_be_positive(L):
    with pytest.raises(ConfigError) as err:
        MemoryIntegrand(L, 1.0, 1.0)
    assert err.value.key == "L" and err.value.allowed == "must be > 0"


def test_the_scene_key_is_checked_by_the_law():
    from solver.config import from_dict

    with pytest.raises(ConfigError) as err:
        from_dict({"memory": {"L": -2.0}})
    assert err.value.key == "memory.L" and err.value.value == -2.0
