"""Per-level diagnostics: the strain norm (at the memory points or from the Gram matrix), damage norms, contact
functionals."""

import numpy as np
import pytest
import ufl
from dolfinx import fem
from mpi4py import MPI

from solver.config import from_dict
from solver.run.model import build_model
from solver.run.stepper import Stepper


@pytest.mark.parametrize("scene", [
    {},  # P1: the norm at the memory points (one per cell)
    {"discretization": {"u_degree": 2}},  # P2: at the degree-3 memory rule's six points
    {"discretization": {"u_degree": 2}, "solver": {"quadrature_degree": 1}},  # a rule too low for eps:eps: the Gram matrix
    {"discretization": {"u_degree": 2}, "time": {"order": 2}},  # the extrapolated history keeps two strains
    {"memory": {"kernel": "none"}},  # no memory: the Gram matrix
], ids=["P1", "P2", "P2-low-rule", "P2-order2", "no-memory"])
def test_strain_norm_and_zeta_norm_equal_their_integrals(comm, scene):
    model = build_model(from_dict({"mesh": {"nx": 4, "ny": 4}, "time": {"T": 0.2, "k": 0.1}, **scene}), comm)
    point_norm = model.mech.diagnostics._point_norm is not None
    assert point_norm == ("memory" not in scene and "solver" not in scene)
    stepper = Stepper(model)
    for n in range(3):
        row = stepper.step(n)
    e = ufl.sym(ufl.grad(model.u))
    want = np.sqrt(comm.allreduce(fem.assemble_scalar(fem.form(ufl.inner(e, e) * ufl.dx)), op=MPI.SUM))
    assert row["strain_norm"] == pytest.approx(want, rel=1e-12)
    z = model.damage.zeta
    want = np.sqrt(comm.allreduce(fem.assemble_scalar(fem.form(z * z * ufl.dx)), op=MPI.SUM))
    assert row["zeta_norm"] == pytest.approx(want, rel=1e-12)
    assert row["zeta_min"] <= row["zeta_max"] <= 1.0


def test_contact_functionals_equal_their_integrals(comm):
    """Example 1 at t = 0: int max(-u_y, 0) / mu over the bottom (written here from scratch), and the pressed length."""
    model = build_model(from_dict({"mesh": {"nx": 8, "ny": 8}, "memory": {"kernel": "none"},
                                   "damage": {"enabled": False}}), comm)
    row = Stepper(model).step(0)
    geo = model.geo
    ds = geo.ds(geo.tags["bottom"], metadata={"quadrature_degree": 2})
    force = fem.form(ufl.max_value(-model.u[1], 0.0) / 1e-10 * ds)
    assert row["contact_force"] == pytest.approx(comm.allreduce(fem.assemble_scalar(force), op=MPI.SUM), rel=1e-12)
    assert row["contact_length"] == pytest.approx(1.0)  # the whole bottom is pressed
    assert row["max_penetration"] > 0.0


def test_contact_traces_in_3d_give_the_force_and_a_finite_max_penetration(comm):
    """On the 6^3 cube of example1_3d the traces live on Γ_C's 7 x 7 vertices; the reported pressure is >= 0, its
    lumped integral Σ m_i p_i is the contact force, and max_penetration (NaN in 3-D before) is finite, positive
    in contact and the largest penetration of the contact profile."""
    from solver.config import load
    from studies import REPO

    cfg = load(REPO / "configs" / "example1_3d.toml", ["mesh.nx=6", "mesh.ny=6", "mesh.nz=6", "time.T=0.02",
                                                       "output.xdmf=false", "solver.linear='mumps'"])
    model = build_model(cfg, comm)
    row = Stepper(model).step(0)
    traces = model.mech.diagnostics.traces
    on = comm.allreduce(int(np.sum(traces.on < traces.pressure.function_space.dofmap.index_map.size_local)))
    assert on == 7 * 7
    assert row["contact_force"] > 0
    assert traces.lumped_force() == pytest.approx(row["contact_force"], rel=1e-12)
    assert comm.allreduce(float(traces.pressure.x.array.min()), op=MPI.MIN) >= 0.0
    assert np.isfinite(row["max_penetration"]) and row["max_penetration"] > 0
    profile = traces.profile()
    top = comm.bcast(max(float(rows[:, 6].max()) for _, rows in profile) if comm.rank == 0 else None, root=0)
    assert row["max_penetration"] == top


@pytest.mark.parametrize("dim", [2, 3])
def test_reactions_assemble_only_the_dirichlet_rows(comm, dim):
    """K_full's Dirichlet rows come from the cells at the Dirichlet dofs alone (issue 30, memory): they equal the
    rows of the whole K assembled without conditions (serial and across ranks), and the matrix Reactions assembles
    holds a small part of K's nonzeros (the whole K was assembled before)."""
    from dolfinx.fem import petsc as fpetsc
    from petsc4py import PETSc

    from solver.config import load
    from solver.physics import diagnostics
    from studies import REPO

    if dim == 2:
        cfg = from_dict({"mesh": {"nx": 24, "ny": 24}, "time": {"T": 0.1, "k": 0.1}})
    else:
        cfg = load(REPO / "configs" / "example1_3d.toml", ["mesh.nx=8", "mesh.ny=8", "mesh.nz=8", "time.T=0.02",
                                                           "output.xdmf=false"])
    model = build_model(cfg, comm)
    reactions = model.mech.diagnostics.reactions
    ops = model.mech.problem.ops
    constrained = ops.dirichlet.constrained
    assert comm.allreduce(len(constrained), op=MPI.SUM) > 0
    part = fpetsc.assemble_matrix(diagnostics.dirichlet_rows_form(ops, constrained))
    part.assemble()
    whole = fpetsc.assemble_matrix(ops.bulk_form)
    whole.assemble()
    assert part.getInfo(PETSc.Mat.InfoType.GLOBAL_SUM)["nz_used"] < 0.2 * whole.getInfo(
        PETSc.Mat.InfoType.GLOBAL_SUM)["nz_used"]
    start, end = whole.getOwnershipRange()
    scale = whole.norm(PETSc.NormType.NORM_INFINITY)
    K = reactions.K  # made at the first use, collectively: on every rank, also one that owns no constrained dof
    for j, dof in enumerate(constrained + start):
        cols, want = whole.getRow(int(dof))
        got_cols, got = K.getRow(K.getOwnershipRange()[0] + j)
        # the same entries; their values the same sums, in parallel possibly added in another order (round-off)
        full = np.zeros(whole.getSize()[1])
        full[cols] = want
        assert set(got_cols[got != 0.0]) == set(cols[want != 0.0])
        assert np.abs(got - full[got_cols]).max(initial=0.0) <= 1e-14 * scale


def _hertz(table: list[list[float]], n: int = 24) -> dict:
    """A half block (0,1) x (0,0.5) pushed 0.005 onto g = x²/2 (μ = 1e-8, P1): the contact zone is about |x| < 0.1."""
    return {"mesh": {"corners": [[0.0, 0.0], [1.0, 0.5]], "nx": 2 * n, "ny": n},
            "memory": {"kernel": "none"}, "damage": {"enabled": False}, "time": {"T": 1.0, "k": 1.0},
            "material": {"E": 100.0, "nu": 0.3, "model": "plane_strain"},
            "boundary": {"left": {"role": "displacement", "displacement": [0.0, "free"]},
                         "top": {"role": "displacement", "displacement": ["free", -0.005]},
                         "bottom": {"role": "contact", "mu": 1e-8, "gap": table, "gap_coordinate": "x"}}}


def _rows(s: np.ndarray) -> list[list[float]]:
    return [[float(a), float(a * a / 2)] for a in s]


def _warnings(comm, table) -> list[str]:
    import logging

    records: list[logging.LogRecord] = []
    handler = logging.Handler()
    handler.emit = records.append  # type: ignore[method-assign]
    logger = logging.getLogger("solver")
    logger.addHandler(handler)
    try:
        model = build_model(from_dict(_hertz(table)), comm)
        Stepper(model).step(0)
        assert model.mech.diagnostics.peak()["peak_pressure"] > 0
    finally:
        logger.removeHandler(handler)
    return [r.getMessage() for r in records if "interpolation error" in r.getMessage()]


def test_table_coarse_only_where_the_body_cannot_reach_does_not_warn(comm):
    """The Hertz scene with rows every 1e-4 where the contact is (x <= 0.15, g <= 0.011) and every 0.01 beyond, where
    the gap is larger than anything under the contact zone: the coarse rows' error (~1.25e-5, ~400 times μ p) is out
    of reach, no warning; the same profile every 0.01 throughout warns once, in one line."""
    fine = np.concatenate([np.arange(0.0, 0.15, 1e-4), np.arange(0.15, 1.0 + 1e-9, 0.01)])
    assert _warnings(comm, _rows(fine)) == []
    coarse = _warnings(comm, _rows(np.arange(0.0, 1.0 + 1e-9, 0.01)))
    assert len(coarse) == 1 and "\n" not in coarse[0] and "boundary.bottom" in coarse[0], coarse


def test_table_coarse_inside_the_contact_zone_still_warns(comm):
    """Fine rows far from the contact do not hide coarse ones under it: every 0.02 for x < 0.2, every 1e-4 beyond."""
    rows = np.concatenate([np.arange(0.0, 0.2, 0.02), np.arange(0.2, 1.0 + 1e-9, 1e-4)])
    found = _warnings(comm, _rows(rows))
    assert len(found) == 1 and "boundary.bottom" in found[0], found
