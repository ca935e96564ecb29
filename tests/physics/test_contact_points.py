"""The contact term at its quadrature points is the UFL term exactly."""


import numpy as np
import pytest
from conftest import ROOT, contact_residuals
from mpi4py import MPI

from solver.config import load
from solver.physics.contact_points import ContactPoints
from solver.physics.quadrature import ContactRule
from solver.run.model import build_model


@pytest.mark.parametrize("points", ["gauss", "nodes"])
@pytest.mark.parametrize("degree", [1, 2])
def test_contact_points_reproduce_the_ufl_contact_term(comm, degree, points):
    """N^T W p(N u - g) equals the assembled contact residual, and N u - g is the penetration (P1 and P2, the law at
    the Gauss points or at the nodes)."""

    cfg = load(ROOT / "configs/hard.toml", ["mesh.nx=8", "mesh.ny=8", f"discretization.u_degree={degree}",
                                            f"solver.contact_points='{points}'"])
    m = build_model(cfg, comm)
    m.mech.solve(0.0)
    pts = ContactPoints(m.geo, m.u.function_space, cfg.contact, ContactRule.of(cfg))
    if points == "nodes":  # the points are u's nodes on Γ_C (each once per facet it closes)
        x = m.u.function_space.tabulate_dof_coordinates()
        on = x[np.isclose(x[:, 1], 0.0)]
        assert {tuple(p) for p in np.round(pts.x, 12)} <= {tuple(p) for p in np.round(on, 12)}
        assert len(pts.W) == 0 or pts.W.min() > 0
    F, G = contact_residuals(m, pts.forces(np.maximum(pts.penetration(m.u.x.array), 0) / cfg.contact[0].mu))
    # both evaluate p = (u.n - g) / mu: the difference of O(|u|) numbers at quadrature points, so
    # round-off of eps |u| is amplified by 1/mu = 1e10 (2e-9 seen with OpenBLAS, 1e-16 with the
    # reference BLAS); a wrong normal, point or weight would differ by O(||F||)
    eps_bound = 10 * np.finfo(float).eps * comm.allreduce(np.abs(m.u.x.array).max(), op=MPI.MAX) / cfg.contact[0].mu
    assert (F - G).norm() <= 1e-14 * F.norm() + eps_bound * m.geo.measure("bottom")
    # total force: sum of W p over the points = the contact-force functional
    r = pts.penetration(m.u.x.array)
    total = comm.allreduce(float((pts.W * np.maximum(r, 0) / cfg.contact[0].mu).sum()), op=MPI.SUM)
    force = m.mech.diagnostics.contact_force()
    # the round-off bound of F - G above applies to both degrees: P2's basis tables (basix's and FFCx's) round
    # differently, and with OpenBLAS P1's u.n differs in its last bits too (1.9e-11 relative here, amplified by 1/mu);
    # a wrong point, weight or normal would differ by O(force)
    assert abs(total - force) <= 1e-12 * abs(force) + eps_bound * m.geo.measure("bottom")
