"""A law's number enters a form on a dolfinx mesh as a fem.Constant (one compiled form for every value), and as a
literal in a bare UFL expression (which UFL's evaluator can evaluate)."""

import numpy as np
import ufl
from dolfinx import fem, mesh
from mpi4py import MPI

from solver.laws.constants import constant
from solver.laws.contact import LinearLaw


def test_a_number_on_a_dolfinx_mesh_is_a_constant_and_the_form_signature_ignores_its_value():
    msh = mesh.create_unit_square(MPI.COMM_WORLD, 2, 2)
    u = fem.Function(fem.FunctionSpace(msh, ("Lagrange", 1)))
    c = constant(u, 2.5)
    assert isinstance(c, fem.Constant) and float(c.value) == 2.5
    forms = [LinearLaw(mu).ufl(u) * ufl.ds for mu in (1e-3, 2e-3)]
    assert forms[0].signature() == forms[1].signature()


def test_a_number_in_a_bare_ufl_expression_is_a_literal():
    domain = ufl.Mesh(ufl.VectorElement("Lagrange", ufl.interval, 1))
    r = ufl.Constant(domain)
    p = LinearLaw(0.5).ufl(ufl.variable(r))
    assert np.isclose(float(p((), {r: 0.25})), 0.5)
