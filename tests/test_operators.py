"""The fixed operators: clamped rows, the load vector of tractions, and the memory term of b_n."""

import numpy as np
import pytest
from mpi4py import MPI

from solver.config import from_dict
from solver.stepper import build_model


def _model(comm, **sections):
    scene = {"mesh": {"nx": 4, "ny": 4}, "damage": {"enabled": False}, **sections}
    return build_model(from_dict(scene), comm)


def test_tractions_sum_to_the_load_on_free_dofs(comm):
    """Example 1's load (-10, -10) on the right side of length 1: nodal forces sum to it (no clamped node there)."""
    model = _model(comm, memory={"kernel": "none"})
    ops = model.mech.ops
    ops.assemble_rhs(0.0)
    n = model.u.function_space.dofmap.index_map.size_local
    b = ops.b.array[: 2 * n].reshape(-1, 2)
    total = comm.allreduce(b.sum(axis=0), op=MPI.SUM)
    assert total == pytest.approx([-10.0, -10.0], rel=1e-12)


def test_clamped_rows_are_identity_and_b_is_zero_there(comm):
    model = _model(comm, memory={"kernel": "none"})
    ops = model.mech.ops
    ops.assemble_rhs(0.0)
    dofs = ops.bcs[0].dof_indices()[0]
    owned = dofs[dofs < ops.K.getLocalSize()[0]]
    start = ops.K.getOwnershipRange()[0]
    for d in owned[:5]:
        cols, vals = ops.K.getRow(start + d)
        assert vals[list(cols).index(start + d)] == pytest.approx(1.0)
        assert np.count_nonzero(vals) == 1
    assert np.all(ops.b.array[owned] == 0.0)
    assert ops.K.isSymmetric(1e-12)


def test_memory_term_enters_b_as_minus_B_M(comm):
    model = _model(comm)
    ops = model.mech.ops
    ops.assemble_rhs(0.0)
    b0 = ops.b.copy()
    model.history.M.x.array[:] = 1.0  # a uniform memory stress
    ops.assemble_rhs(0.0)
    assert np.array_equal(ops.b_prev.array, b0.array)  # the previous b is kept
    # (M, eps(w)) for a uniform M is the boundary term int (M n) . w: summed over all nodes it is zero, so over
    # the free ones (the clamped rows of b are zero) it is minus the clamped side's -int_left M n = (1, 1)
    n = model.u.function_space.dofmap.index_map.size_local
    diff = (b0.array - ops.b.array)[: 2 * n]
    total = comm.allreduce(diff.reshape(-1, 2).sum(axis=0), op=MPI.SUM)
    assert total == pytest.approx([1.0, 1.0], rel=1e-12)
