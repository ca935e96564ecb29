"""The contact traces factor only the Γ_C block of the boundary mass matrix (issue 30, start-up): the whole matrix
(1 on the diagonal off Γ_C, a volume stencil's pattern) filled like a volume Laplacian, 5 s to factor at 36,501 dofs
in 3-D. λ_h still solves its projection equation (λ_h, ψ)_Γ_C = Σ_q p(u_ν − g) ψ w_q, and is 0 off Γ_C."""

import numpy as np
import pytest
import ufl
from dolfinx import fem
from dolfinx.fem import petsc as fpetsc
from mpi4py import MPI
from petsc4py import PETSc

from solver.config import from_dict
from solver.run.model import build_model

SCENES = {
    "2d": {"mesh": {"nx": 6, "ny": 5}},
    "3d": {"mesh": {"kind": "box", "corners": [[0, 0, 0], [1, 1, 1]], "nx": 3, "ny": 4, "nz": 3},
           "material": {"model": "3d"},
           "boundary": {"left": {"role": "clamped"}, "right": {"role": "traction", "traction": [0.0, 0.0, -1.0]},
                        "bottom": {"role": "contact", "gap": 0.0, "mu": 1e-10}}},
}


@pytest.mark.parametrize("scene", sorted(SCENES))
def test_the_factored_matrix_is_the_contact_block_and_lambda_solves_the_projection(comm, scene):
    model = build_model(from_dict({**SCENES[scene], "memory": {"kernel": "none"}, "damage": {"enabled": False}}),
                        comm)
    traces = model.mech.diagnostics.traces
    S = traces.pressure.function_space
    # every Γ_C dof once, whichever rank holds its facets: the global dofs on the contact facets of all ranks
    imap = S.dofmap.index_map
    mine = imap.local_to_global(traces.on.astype(np.int32))
    on_global = np.unique(np.concatenate(comm.allgather(mine)))
    A, _ = traces.ksp.getOperators()
    assert A.getSize() == (len(on_global), len(on_global))
    assert traces.is_on.getSize() == len(on_global)
    # a penetration that varies along Γ_C; λ_h against its projection equation, assembled here
    model.u.interpolate(lambda x: np.vstack([0.0 * x[0]] * (model.geo.dim - 1) + [-1e-9 * (1 + x[0] + x[0] ** 2)]))
    traces.update()
    psi, lam = ufl.TestFunction(S), ufl.TrialFunction(S)
    M = fpetsc.assemble_matrix(fem.form(lam * psi * model.geo.ds(model.geo.tags["bottom"],
                                                                 metadata={"quadrature_degree": 2})))
    M.assemble()
    b = fpetsc.create_vector(traces.rhs[traces.pressure])
    fpetsc.assemble_vector(b, traces.rhs[traces.pressure])
    b.ghostUpdate(addv=PETSc.InsertMode.ADD, mode=PETSc.ScatterMode.REVERSE)
    residual = b.duplicate()
    M.mult(traces.pressure.vector, residual)
    residual.axpy(-1.0, b)
    assert b.norm() > 0
    assert residual.norm() <= 1e-12 * b.norm()
    n_local = imap.size_local
    off = np.setdiff1d(np.arange(n_local), traces.on)
    assert comm.allreduce(int(np.count_nonzero(traces.pressure.x.array[off])), op=MPI.SUM) == 0
