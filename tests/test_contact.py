"""The contact term: the compliance law, and the Jacobian's active set tracked between calls."""

import numpy as np
import pytest
from conftest import eval_point, unit_mesh
from dolfinx import fem
from mpi4py import MPI

from solver.config import from_dict
from solver.contact import normal_compliance
from solver.stepper import build_model


def test_normal_compliance_is_the_positive_part_over_mu(comm):
    mesh = unit_mesh(comm)
    for r, want in ((0.3, 0.3 / 1e-2), (-0.3, 0.0)):
        assert eval_point(normal_compliance(fem.Constant(mesh, r), 1e-2), mesh) == pytest.approx(want)


def test_jacobian_is_rebuilt_only_when_the_active_set_changes(comm):
    cfg = from_dict({"mesh": {"nx": 4, "ny": 4}, "memory": {"kernel": "none"}, "damage": {"enabled": False}})
    model = build_model(cfg, comm)
    term = model.mech.contact
    assert term.assemble_jacobian()  # the first call is new
    assert not term.assemble_jacobian()  # same u: same active set
    x = model.u.function_space.tabulate_dof_coordinates()
    u = model.u.x.array.reshape(-1, 2)
    u[:, 1] = -1e-3 * (x[:, 0] < 0.5)  # the left half of the bottom now penetrates
    model.u.x.scatter_forward()
    assert term.assemble_jacobian()
    u[:, 1] *= 2.0  # deeper, same points active: the Jacobian H(r)/mu is the same
    assert not term.assemble_jacobian()
    term.forget()
    assert term.assemble_jacobian()
    assert np.isfinite(term.C.norm())


def test_contact_term_is_the_ufl_residual(comm):
    cfg = from_dict({"mesh": {"nx": 4, "ny": 4}, "memory": {"kernel": "none"}, "damage": {"enabled": False}})
    model = build_model(cfg, comm)
    model.u.x.array[1::2] = -1e-3  # the whole body moved down by 1e-3
    F = model.mech.ops.b.duplicate()
    F.set(0.0)
    norm = model.mech.contact.add_residual(F)
    total = comm.allreduce(float(F.array[1::2].sum()), op=MPI.SUM)
    # sum of int p(u_nu - g) w_nu over the bottom for w = the y hat functions: p = 1e-3 / 1e-10 on a
    # length 1 with the outward normal -e_y, less the clamped corner's half cell (its row is zero)
    assert total == pytest.approx(-(1e-3 / 1e-10) * (1 - 1 / 8), rel=1e-10)
    assert norm == pytest.approx(F.norm())
