"""The written cell stresses (solver/io/fields.py) equal the L2 projection onto cell constants assembled from UFL."""

import numpy as np
import pytest
import ufl
from conftest import ROOT
from dolfinx import fem
from dolfinx.fem import petsc as fpetsc
from petsc4py import PETSc

from solver.config import from_dict, load
from solver.io.fields import CellStresses, Outputs
from solver.physics.material import elasticity, strain, von_mises_array
from solver.run.model import build_model
from solver.run.stepper import Stepper


def projection(expr, mesh, dx) -> np.ndarray:
    """(integral of expr over K) / |K| for the owned cells K, by assembly (the reference)."""
    T0 = fem.TensorFunctionSpace(mesh, ("DG", 0))
    S0 = fem.FunctionSpace(mesh, ("DG", 0))
    b = fpetsc.assemble_vector(fem.form(ufl.inner(expr, ufl.TestFunction(T0)) * dx))
    b.ghostUpdate(addv=PETSc.InsertMode.ADD, mode=PETSc.ScatterMode.REVERSE)
    vol = fpetsc.assemble_vector(fem.form(ufl.TestFunction(S0) * ufl.dx))
    vol.ghostUpdate(addv=PETSc.InsertMode.ADD, mode=PETSc.ScatterMode.REVERSE)
    n = T0.dofmap.index_map.size_local
    d = mesh.geometry.dim
    values = b.array_r.reshape(n, d * d) / vol.array_r[:n, None]
    imap = mesh.topology.index_map(mesh.topology.dim)
    cell_dof = T0.dofmap.list.array.reshape(imap.size_local + imap.num_ghosts, -1)[: imap.size_local, 0]
    return values[cell_dof]


@pytest.mark.parametrize("degree,model", [(1, "plane_stress"), (2, "plane_stress"), (1, "plane_strain")])
def test_cell_stresses_equal_the_assembled_projection(comm, degree, model):
    """Example 1 (memory, damage) after 5 steps, with 1- and 3-point memory rules, serial and on 2 ranks."""
    cfg = load(ROOT / "configs/example1.toml", ["mesh.nx=6", "mesh.ny=6", "time.k=0.05",
                                                f"solver.quadrature_degree={degree}", f"material.model={model}"])
    model = build_model(cfg, comm)
    stepper = Stepper(model)
    for n in range(6):
        stepper.step(n)
    mesh, mat = model.geo.mesh, cfg.material
    sig_el = elasticity(strain(model.u), mat.E, mat.nu, mat.model)
    want_el = projection(sig_el, mesh, model.rule.dx)
    want = projection(sig_el + model.history.M, mesh, model.rule.dx)
    assert np.abs(want - want_el).max() > 1.0  # the memory term is not negligible here
    cs = CellStresses(model, mat)
    got_el = cs.elastic()
    got = cs.total(got_el)
    scale = np.abs(want).max()
    assert np.allclose(got_el, want_el, rtol=0, atol=1e-13 * scale)
    assert np.allclose(got, want, rtol=0, atol=1e-13 * scale)
    fields = Outputs(model, mat, cfg.output, None).names  # no directory: nothing written, nothing built
    assert fields == ["displacement", "damage", "von_mises", "von_mises_elastic"]
    assert np.allclose(von_mises_array(got, 2), von_mises_array(want, 2), rtol=1e-13)


@pytest.mark.parametrize("u_degree", [1, 2])
def test_implicit_trapezoid_stress_includes_the_current_level(comm, u_degree):
    """With memory.rule = "trapezoid" the history keeps the past only; sigma_n = A eps(u_n) + M_n + (k/2) g(0) H_n."""
    from solver.physics.memory import memory_source

    cfg = load(ROOT / "configs/example1.toml", ["mesh.nx=6", "mesh.ny=6", "time.k=0.05", "memory.rule='trapezoid'",
                                                f"discretization.u_degree={u_degree}"])
    model = build_model(cfg, comm)
    stepper = Stepper(model)
    for n in range(4):
        stepper.step(n)
    mesh, mat = model.geo.mesh, cfg.material

    def A(e):
        return elasticity(e, mat.E, mat.nu, mat.model)

    weight = float(model.history.current_weight.value)
    assert weight == pytest.approx(0.5 * 0.05 * 1.0)
    H = memory_source(model.u, model.zeta, A, cfg.memory.L)
    want = projection(A(strain(model.u)) + model.history.M + weight * H, mesh, model.rule.dx)
    cs = CellStresses(model, mat)
    got = cs.total(cs.elastic())
    assert np.allclose(got, want, rtol=0, atol=1e-12 * np.abs(want).max())


@pytest.mark.parametrize("u_degree,memory", [(1, True), (1, False), (2, False)])
def test_cell_stresses_in_3d_with_and_without_memory(comm, u_degree, memory):
    """3-D Example 1: the strains from the history's source (memory) or from the writer's own gradient table at the
    centroids (no memory; P1 and P2) give the assembled projection's cell averages."""
    sets = ["mesh.nx=3", "mesh.ny=3", "mesh.nz=3", "time.k=0.05", f"discretization.u_degree={u_degree}",
            "solver.linear='mumps'"]
    cfg = load(ROOT / "configs/example1_3d.toml", sets)
    if not memory:
        document = {**cfg.document, "memory": {"kernel": "none"}}
        cfg = from_dict(document, base=ROOT / "configs")
    model = build_model(cfg, comm)
    stepper = Stepper(model)
    for n in range(3):
        stepper.step(n)
    assert (model.history is not None) == memory
    mesh, mat = model.geo.mesh, cfg.material
    sig_el = elasticity(strain(model.u), mat.E, mat.nu, mat.model)
    want_el = projection(sig_el, mesh, ufl.dx(metadata={"quadrature_degree": 2}))
    cs = CellStresses(model, mat)
    got_el = cs.elastic()
    scale = np.abs(want_el).max()
    assert scale > 0
    assert np.allclose(got_el, want_el, rtol=0, atol=1e-13 * scale)
    if memory:
        want = projection(sig_el + model.history.M, mesh, model.rule.dx)
        assert np.allclose(cs.total(got_el), want, rtol=0, atol=1e-13 * np.abs(want).max())


def test_cell_fields_in_blocks_equal_the_whole(comm, shared_tmp, monkeypatch):
    """Outputs computes the cell fields block by block (only the written arrays whole): blocks of 7 cells give the
    stresses and von Mises values of CellStresses over all cells at once."""
    cfg = load(ROOT / "configs/example1.toml", ["mesh.nx=6", "mesh.ny=6", "time.k=0.05", "material.model='plane_strain'",
                                                "solver.quadrature_degree=2"])
    cfg = cfg.replace({"output": {"fields": ["stress", "elastic_stress", "von_mises", "von_mises_elastic",
                                             "stress_zz"]}})
    model = build_model(cfg, comm)
    stepper = Stepper(model)
    for n in range(3):
        stepper.step(n)
    monkeypatch.setattr(Outputs, "BLOCK", 7)
    out = Outputs(model, cfg.material, cfg.output, shared_tmp)
    got = out.cell_fields()
    cs = CellStresses(model, cfg.material)
    elastic = cs.elastic()
    total = cs.total(elastic)
    zz, zz_el = cs.out_of_plane()
    assert np.array_equal(got["elastic_stress"], elastic) and np.array_equal(got["stress"], total)
    assert np.array_equal(got["stress_zz"], zz) and np.array_equal(got["elastic_stress_zz"], zz_el)
    assert np.array_equal(got["von_mises"], von_mises_array(total, 2, zz))
    assert np.array_equal(got["von_mises_elastic"], von_mises_array(elastic, 2, zz_el))
    assert len(elastic) > 7 and np.abs(total - elastic).max() > 0
    out.close()


@pytest.mark.parametrize("memory,fields", [(True, ("von_mises", "von_mises_elastic")), (True, ("von_mises",)),
                                           (False, ("von_mises_elastic",)), (False, ("von_mises", "von_mises_elastic"))])
def test_plane_von_mises_in_place_equal_the_tensor_formula(comm, shared_tmp, monkeypatch, memory, fields):
    """In plane stress the von Mises values alone are computed from the components, in place, block by block (blocks of
    7 cells, and the whole at once): bit for bit von_mises_array of the stress tensors, with and without memory, at
    two levels (the work arrays kept between them)."""
    cfg = load(ROOT / "configs/example1.toml", ["mesh.nx=6", "mesh.ny=6", "time.k=0.05"])
    if not memory:
        cfg = from_dict({**cfg.document, "memory": {"kernel": "none"}}, base=ROOT / "configs")
    cfg = cfg.replace({"output": {"fields": list(fields)}})
    model = build_model(cfg, comm)
    assert (model.history is not None) == memory
    stepper = Stepper(model)
    stepper.step(0)
    outs = [Outputs(model, cfg.material, cfg.output, shared_tmp)]
    monkeypatch.setattr(Outputs, "BLOCK", 7)
    outs.append(Outputs(model, cfg.material, cfg.output, shared_tmp))
    for n in (1, 2):
        stepper.step(n)
        cs = CellStresses(model, cfg.material)
        elastic = cs.elastic()
        want = {"von_mises": von_mises_array(cs.total(elastic), 2), "von_mises_elastic": von_mises_array(elastic, 2)}
        assert len(elastic) > 7 and (not memory or np.abs(want["von_mises"] - want["von_mises_elastic"]).max() > 0)
        for out in outs:
            got = out.cell_fields()
            assert set(got) == set(fields)
            for name in fields:
                assert np.array_equal(got[name], want[name]), name
    for out in outs:
        out.close()


def test_written_cell_fields_do_not_hold_the_levels_strain(comm, shared_tmp):
    """After a level's cell fields the writer holds neither the memory source's kept strain nor the memory tensor: the
    next level's strain would otherwise be made beside this one (27 MiB each at 311,469 dofs in 3-D); the next
    level's fields are those of its own strain."""
    import gc
    import weakref

    cfg = load(ROOT / "configs/example1.toml", ["mesh.nx=6", "mesh.ny=6", "time.k=0.05"])
    cfg = cfg.replace({"output": {"fields": ["stress", "von_mises"]}})
    model = build_model(cfg, comm)
    stepper = Stepper(model)
    stepper.step(0)
    out = Outputs(model, cfg.material, cfg.output, shared_tmp)
    first = out.cell_fields()
    strain = weakref.ref(model.history.H.strain())
    st = out.stresses
    assert st._eps is None and st._memory is None
    stepper.step(1)
    gc.collect()
    assert strain() is None  # the source let it go, and nothing else held it
    second = out.cell_fields()
    cs = CellStresses(model, cfg.material)
    assert np.array_equal(second["stress"], cs.total(cs.elastic()))
    assert np.abs(second["stress"] - first["stress"]).max() > 0
    out.close()
