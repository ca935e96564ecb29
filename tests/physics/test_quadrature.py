"""The contact term's facet rule (ContactRule): Gauss as before, or the facets' nodes; and the nodal contact term is
the sum over Γ_C's nodes of m_i p(u_ν - g)(x_i) n φ_i, m_i = ∫ φ_i ds, assembled here by hand."""

import basix
import numpy as np
import pytest
import ufl
from dolfinx import fem
from dolfinx.fem import petsc as fpetsc
from mpi4py import MPI
from petsc4py import PETSc

from solver.config import from_dict
from solver.physics.gap import gap_values
from solver.physics.quadrature import ContactRule, contact_rule, facet_type
from solver.run.model import build_model

STATIC = {"memory": {"kernel": "none"}, "damage": {"enabled": False}, "time": {"T": 1.0, "k": 1.0}}


def test_gauss_is_the_degree_as_before():
    """The default rule's ds metadata is the degree alone (the forms, and so the results, are main's)."""
    assert contact_rule(3) == ContactRule(3, "gauss", 1)
    assert ContactRule(4).metadata(basix.CellType.interval) == {"quadrature_degree": 4}
    for cell in (basix.CellType.interval, basix.CellType.triangle):
        x, w = ContactRule(2).facet_quadrature(cell)
        x0, w0 = basix.make_quadrature(cell, 2)
        assert np.array_equal(x, x0) and np.array_equal(w, w0)


@pytest.mark.parametrize("cell, order, points, weights", [
    (basix.CellType.interval, 1, [[0.0], [1.0]], [0.5, 0.5]),                   # trapezoid: the P1 nodes
    (basix.CellType.interval, 2, [[0.0], [1.0], [0.5]], [1 / 6, 1 / 6, 2 / 3]),  # Simpson: the P2 nodes
    (basix.CellType.triangle, 1, [[0.0, 0.0], [1.0, 0.0], [0.0, 1.0]], [1 / 6, 1 / 6, 1 / 6]),  # the vertices
])
def test_nodal_rule_sits_at_the_nodes(cell, order, points, weights):
    x, w = ContactRule(9, "nodes", order).facet_quadrature(cell)
    assert np.allclose(x, points, atol=1e-15) and np.allclose(w, weights, rtol=1e-14)
    md = ContactRule(9, "nodes", order).metadata(cell)
    assert md["quadrature_rule"] == "custom" and np.array_equal(md["quadrature_points"], x)


def test_no_nodal_rule_for_p2_triangles():
    with pytest.raises(ValueError, match="P2 on triangle"):
        ContactRule(4, "nodes", 2).facet_quadrature(basix.CellType.triangle)


def _scene(dim: int, degree: int, n: int) -> dict:
    if dim == 2:
        return {**STATIC, "mesh": {"nx": n, "ny": n}, "discretization": {"u_degree": degree},
                "boundary": {"left": {"role": "clamped"},
                             "bottom": {"role": "contact", "mu": 1e-2,
                                        "obstacle": {"shape": "circle", "centre": [0.4, -1.0], "radius": 1.0}}},
                "solver": {"contact_points": "nodes"}}
    return {**STATIC, "mesh": {"kind": "box", "nx": n, "ny": n, "nz": 2}, "material": {"model": "3d"},
            "boundary": {"left": {"role": "clamped"},
                         "bottom": {"role": "contact", "mu": 1e-2,
                                    "obstacle": {"shape": "sphere", "centre": [0.4, 0.5, -1.0], "radius": 1.0}}},
            "solver": {"contact_points": "nodes"}}


@pytest.mark.parametrize("dim, degree", [(2, 1), (2, 2), (3, 1)])
def test_nodal_contact_term_is_the_sum_at_the_nodes(comm, dim, degree):
    """With ``contact_points = "nodes"`` the assembled j(u, w) is, at each node x_i of Γ_C (z = 0 or y = 0, normal
    -e_dim), -m_i max(-u_dim(x_i) - g(x_i), 0) / mu in the normal component and 0 elsewhere, m_i = ∫ φ_i ds (the
    Newton-Cotes weights are the basis' exact integrals: h/2 | h (P1), h/6 | 2h/3 (P2), area/3 (P1 triangles)),
    with u a smooth field that penetrates over part of Γ_C only; serial and parallel."""
    model = build_model(from_dict(_scene(dim, degree, 4)), comm)
    u = model.u
    u.interpolate(lambda x: np.stack([0.01 * x[1]] * (dim - 1) + [-0.02 + 0.03 * x[0] ** 2 + 0.01 * x[1]]))
    u.x.scatter_forward()
    F = model.mech.ops.b.duplicate()
    with F.localForm() as f:
        f.set(0.0)
    fpetsc.assemble_vector(F, model.mech.contact.residual_form)
    F.ghostUpdate(addv=PETSc.InsertMode.ADD, mode=PETSc.ScatterMode.REVERSE)
    # m_i = ∫ φ_i ds over Γ_C, with the exact Gauss rule
    V = u.function_space
    S = fem.FunctionSpace(model.geo.mesh, ("Lagrange", degree))
    m = fpetsc.assemble_vector(fem.form(ufl.TestFunction(S) * model.geo.ds(model.geo.tags["bottom"],
                                                                             metadata={"quadrature_degree": 4})))
    m.ghostUpdate(addv=PETSc.InsertMode.ADD, mode=PETSc.ScatterMode.REVERSE)
    owned = V.dofmap.index_map.size_local
    x = V.tabulate_dof_coordinates()[:owned]
    part = next(b for b in model.cfg.boundaries if b.role == "contact")
    values = u.x.array.reshape(-1, dim)[:owned]
    mu = part.contact_law.compliance
    expected = np.zeros((owned, dim))
    expected[:, dim - 1] = -m.array_r[:owned] * np.maximum(-values[:, dim - 1] - gap_values(part, x[:, :dim]), 0) / mu
    on = m.array_r[:owned] > 0
    assert np.array_equal(on, np.isclose(x[:, dim - 1], 0.0))  # the contact nodes: z = 0 (y = 0)
    got = F.array_r.reshape(-1, dim)
    scale = comm.allreduce(float(np.abs(expected).max(initial=0.0)), op=MPI.MAX)
    active = comm.allreduce(int((expected[:, dim - 1] < 0).sum()), op=MPI.SUM)
    total = comm.allreduce(int(on.sum()), op=MPI.SUM)
    assert 0 < active < total  # the law acts at some nodes and not at others
    # round-off: u(x_i) is a sum over the cell's n_b basis functions tabulated at the node (n_b eps |u| each), u_nu - g
    # one more rounding of |u| + |g|, both times m_i / mu; the weights, Jacobians and normal a few eps of the entry
    n_b = V.dofmap.dof_layout.num_dofs
    g = np.abs(gap_values(part, x[:, :dim]))
    size = comm.allreduce(float(np.max(m.array_r[:owned][on] * (np.abs(values).max(initial=0.0) + g[on]),
                                       initial=0.0)), op=MPI.MAX) / mu
    eps = np.finfo(float).eps
    assert comm.allreduce(float(np.abs(got - expected).max(initial=0.0)), op=MPI.MAX) <= (
        (n_b + 2) * eps * size + 4 * eps * scale)
    # the force functional is the weighted sum at the nodes too
    force = model.mech.diagnostics.contact_force()
    assert force == pytest.approx(comm.allreduce(float(-expected[:, dim - 1].sum()), op=MPI.SUM), rel=1e-12)


def test_facet_type():
    from dolfinx import mesh

    assert facet_type(mesh.create_unit_square(MPI.COMM_SELF, 1, 1)) == basix.CellType.interval
    assert facet_type(mesh.create_unit_cube(MPI.COMM_SELF, 1, 1, 1)) == basix.CellType.triangle


@pytest.mark.parametrize("dim, degree", [(2, 2), (3, 1)])
def test_pressures_of_the_nodal_rule_carry_its_force(comm, dim, degree):
    """The reported pressure (traces) and the estimator's λ_h are recovered with the nodal rule too: both integrate
    to the contact force of the nodal term (a Gauss rule anywhere in them would not)."""
    from solver.physics.estimator import estimator_for

    model = build_model(from_dict(_scene(dim, degree, 4)), comm)
    model.u.interpolate(lambda x: np.stack([0.01 * x[1]] * (dim - 1) + [-0.02 + 0.03 * x[0] ** 2 + 0.01 * x[1]]))
    model.u.x.scatter_forward()
    force = model.mech.diagnostics.contact_force()
    traces = model.mech.diagnostics.traces
    traces.update()
    assert traces.lumped_force() == pytest.approx(force, rel=1e-12)
    pressure = estimator_for(model).pressure
    pressure.update()
    ds = model.geo.ds(model.geo.tags["bottom"], metadata={"quadrature_degree": 2 * degree})
    total = comm.allreduce(fem.assemble_scalar(fem.form(pressure.pressure * ds)), op=MPI.SUM)
    assert total == pytest.approx(force, rel=1e-9)  # λ_h by CG to 1e-14 on the boundary mass matrix
