"""Constitutive functions against hand values: A (plane stress/strain), Phi_L, von Mises."""

import numpy as np
import pytest
from conftest import eval_point, unit_mesh
from dolfinx import fem

from solver.physics.material import elasticity, lame, out_of_plane_stress, strain, truncate, von_mises, von_mises_array


def test_plane_stress_matches_paper_formula(comm):
    m = unit_mesh(comm)
    E, r = 100.0, 0.3
    tau = np.array([[0.01, 0.02], [0.02, -0.03]])
    got = eval_point(elasticity(fem.Constant(m, tau), E, r, "plane_stress"), m)
    # (A tau)_ab = E r / (1 - r^2) (tau11 + tau22) delta_ab + E / (1 + r) tau_ab
    want = E * r / (1 - r**2) * np.trace(tau) * np.eye(2) + E / (1 + r) * tau
    assert np.allclose(got, want, rtol=1e-14, atol=1e-14)


def test_plane_strain_lame():
    lam, mu = lame(210.0, 0.25, "plane_strain")
    assert lam == pytest.approx(210 * 0.25 / (1.25 * 0.5))
    assert mu == pytest.approx(210 / 2.5)


def test_truncation_componentwise(comm):
    m = unit_mesh(comm)
    tau = np.array([[1500.0, -2000.0], [3.0, -999.0]])
    got = eval_point(truncate(fem.Constant(m, tau), 1000.0), m)
    assert np.array_equal(got, np.array([[1000.0, -1000.0], [3.0, -999.0]]))


def test_von_mises_hand_value(comm):
    m = unit_mesh(comm)
    tau = np.array([[3.0, 1.0], [1.0, -2.0]])
    want = np.sqrt(9 + 4 + 6 + 3)  # t11^2 + t22^2 - t11 t22 + 3 t12^2
    assert eval_point(von_mises(fem.Constant(m, tau)), m) == pytest.approx(want, rel=1e-14)
    assert von_mises_array(tau.ravel(), 2)[0] == pytest.approx(want, rel=1e-14)


def test_von_mises_3d_uniaxial():
    s = np.diag([7.0, 0.0, 0.0]).ravel()
    assert von_mises_array(s, 3)[0] == pytest.approx(7.0, rel=1e-14)


def test_strain_of_linear_field_is_exact(comm):
    m = unit_mesh(comm)
    V = fem.VectorFunctionSpace(m, ("CG", 1))
    u = fem.Function(V)
    u.interpolate(lambda x: np.vstack([2 * x[0] + 3 * x[1], -x[0] + 5 * x[1]]))
    got = eval_point(strain(u), m)  # grad u = [[2, 3], [-1, 5]]: only its symmetric part is the strain
    assert np.allclose(got, [[2.0, 1.0], [1.0, 5.0]], atol=1e-13)


def test_von_mises_plane_strain_uses_sigma_33(comm):
    """sqrt(((s11-s22)^2 + (s22-s33)^2 + (s33-s11)^2)/2 + 3 s12^2); with s33 = 0 the paper's plane formula."""
    m = unit_mesh(comm)
    tau = np.array([[3.0, 1.0], [1.0, -2.0]])
    s33 = 4.0
    want = np.sqrt(((3 + 2) ** 2 + (-2 - 4) ** 2 + (4 - 3) ** 2) / 2 + 3)
    assert eval_point(von_mises(fem.Constant(m, tau), fem.Constant(m, s33)), m) == pytest.approx(want, rel=1e-14)
    assert von_mises_array(tau.ravel(), 2, np.array([s33]))[0] == pytest.approx(want, rel=1e-14)
    assert von_mises_array(tau.ravel(), 2, np.array([0.0]))[0] == pytest.approx(von_mises_array(tau.ravel(), 2)[0], rel=1e-14)
    # sigma_33 of A in plane strain: lambda (eps11 + eps22)
    eps = np.array([[0.01, 0.002], [0.002, -0.004]])
    lam, _ = lame(100.0, 0.3, "plane_strain")
    assert eval_point(out_of_plane_stress(fem.Constant(m, eps), 100.0, 0.3), m) == pytest.approx(lam * 0.006, rel=1e-14)
