"""studies/memory3d.py: the memory breakdown of a 3-D run (stages, arrays held, PETSc matrices)."""

import numpy as np
import pytest

from studies import memory3d


def test_allocated_counts_the_base_a_view_keeps_alive():
    base = np.zeros(100)
    assert memory3d._allocated(base[:10]) == base.nbytes == memory3d._allocated(base)


@pytest.mark.serial
def test_breakdown_lists_the_stages_the_strain_operator_and_the_matrices():
    m = memory3d.measure(3, "iterative")  # as the CLI runs it: written levels and a checkpoint
    assert m["dofs"] == 3 * 4 ** 3 and list(m["stages_mib"])[:3] == ["imports", "build_model", "level 0 (written)"]
    assert "level 2 (written)" in m["stages_mib"]
    bare = memory3d.measure(3, "iterative", outputs=False)
    assert list(bare["stages_mib"])[:3] == ["imports", "build_model", "level 0"]
    E = sum(v for k, v in m["arrays"].items() if k.startswith("model.history.H.strain_operator"))
    assert E > 0 and any(s == (m["dofs"], m["dofs"]) for _, s, _ in m["matrices"])
    text = memory3d.report(m)
    assert "| build_model |" in text and "`model.history.H.strain_operator._grad`" in text


def test_strain_operator_holds_no_unsummed_duplicates():
    """E of the memory source (2-D: a sparse matrix) keeps one entry per (row, column): its buffers are not larger
    than its nonzeros (scipy's tocsr of a COO with duplicates keeps the unsummed buffer alive behind the summed
    slice)."""
    from mpi4py import MPI

    from solver.config import load
    from solver.run.model import build_model
    from studies import REPO

    cfg = load(REPO / "configs" / "example1.toml", ["mesh.nx=4", "mesh.ny=4", "output.xdmf=false"])
    E = build_model(cfg, MPI.COMM_WORLD).history.H.strain_operator
    assert memory3d._allocated(E.data) == E.nnz * E.data.itemsize
    assert memory3d._allocated(E.indices) == E.nnz * E.indices.itemsize


def test_the_3d_strain_operator_takes_a_quarter_kb_per_dof():
    """Issue 30: in 3-D E is a table of the basis gradients (StrainMap), 0.2 KB per displacement dof of P1
    tetrahedra; the sparse matrix took 0.83 KB."""
    from mpi4py import MPI

    from solver.config import load
    from solver.run.model import build_model
    from studies import REPO

    cfg = load(REPO / "configs" / "example1_3d.toml", ["mesh.nx=8", "mesh.ny=8", "mesh.nz=8", "output.xdmf=false"])
    model = build_model(cfg, MPI.COMM_WORLD)
    held = memory3d.arrays_held(model)
    E = sum(v for k, v in held.items() if k.startswith("model.history.H.strain_operator"))
    dofs = model.u.function_space.dofmap.index_map.size_global * 3
    assert E / dofs < 250


def test_memory_term_keeps_one_operator_and_no_idle_buffers():
    """Issue 30, memory: besides the strain operator E, the memory term of 3-D Example 1 (one Prony term, order 1)
    holds at most five arrays of M's size (M, the kept strain, A eps, the force's W m, zeta at the points and
    the weights are each M's or smaller); E^T W stored beside E, the idle extrapolation buffer and the
    several-term increment took four more."""
    from mpi4py import MPI

    from solver.config import load
    from solver.run.model import build_model
    from studies import REPO

    cfg = load(REPO / "configs" / "example1_3d.toml", ["mesh.nx=4", "mesh.ny=4", "mesh.nz=4", "time.T=0.04",
                                                       "output.xdmf=false"])
    model = build_model(cfg, MPI.COMM_WORLD)
    held = memory3d.arrays_held(model)
    M = held["model.history.M.x"]
    memory = {k: v for k, v in held.items() if k.startswith(("model.history", "model.mech.ops._memory_force"))
              and "strain_operator" not in k}
    assert sum(memory.values()) <= 5 * M, sorted(memory.items(), key=lambda kv: -kv[1])
