"""solver/physics/memory_source.py in 3-D: the strain operator kept as a table of basis gradients (StrainMap)
gives the products of the sparse matrix it replaces, and the memory source the UFL definition."""

import numpy as np
import pytest
import ufl
from dolfinx import fem, mesh
from mpi4py import MPI

from solver.laws.memory import MemoryIntegrand
from solver.physics.material import elasticity, lame, strain
from solver.physics.memory import memory_source
from solver.physics.memory_source import MemoryForce, MemorySource, StrainMap, sparse_strain_operator
from solver.physics.quadrature import QuadratureRule


def _box(comm, degree: int):
    m = mesh.create_unit_cube(comm, 3, 3, 3)
    u = fem.Function(fem.VectorFunctionSpace(m, ("CG", degree)))
    u.interpolate(lambda x: np.vstack([x[0] ** 2 + x[1] * x[2], np.sin(3 * x[1]) * x[0], x[2] ** 3 - x[0] * x[1]]))
    zeta = fem.Function(fem.FunctionSpace(m, ("CG", 1)))
    zeta.interpolate(lambda x: 0.3 + 0.5 * x[0] * x[1])
    return m, u, zeta, QuadratureRule(m, 2 * (degree - 1) + 1)


@pytest.mark.parametrize("degree", [1, 2])
def test_the_table_gives_the_sparse_matrix_products(comm, degree):
    """E u and E^T m of the table equal those of the sparse matrix built from the same gradients (2-D's), to
    round-off; the table takes a third of the matrix's bytes or less (a quarter at 10^5 dofs)."""
    _, u, zeta, rule = _box(comm, degree)
    source = MemorySource(rule, u, zeta, MemoryIntegrand(1e30, *lame(100.0, 0.3, "plane_strain")))
    E = source.strain_operator
    assert isinstance(E, StrainMap)
    S = sparse_strain_operator(E.grad, E.nodes, E.bs, E.rows_q, E.size_q, E.size_v, E.pairs)
    x = np.random.default_rng(0).standard_normal(E.shape[1])
    m = np.random.default_rng(1).standard_normal(E.shape[0])
    a, b = E @ x, S @ x
    assert np.abs(a - b).max() <= 1e-14 * np.abs(b).max()
    a, b = E.T @ m, S.T @ m
    assert np.abs(a - b).max() <= 1e-14 * np.abs(b).max()
    table = E.grad.nbytes + E.nodes.nbytes + E.rows_q.nbytes
    assert 3 * table <= S.data.nbytes + S.indices.nbytes + S.indptr.nbytes


def test_the_3d_source_and_force_equal_their_definitions(comm):
    """H = zeta Phi_L(A eps(u)) (truncation acting) and B M = (M, eps(w)) in 3-D against UFL."""
    m, u, zeta, rule = _box(comm, 1)
    lam, mu = lame(100.0, 0.3, "plane_strain")
    L = 60.0
    source = MemorySource(rule, u, zeta, MemoryIntegrand(L, lam, mu))

    def A(eps):
        return elasticity(eps, 100.0, 0.3, "plane_strain")

    ref = rule.evaluator(memory_source(u, zeta, A, L), source.Q)()
    a = source()
    assert np.allclose(a, ref, rtol=1e-13, atol=1e-12 * np.abs(ref).max())
    raw = rule.evaluator(A(strain(u)), source.Q)()
    assert comm.allreduce(np.abs(raw).max(), op=MPI.MAX) > L  # the truncation acts
    M = fem.Function(source.Q)
    M.x.array[:] = a
    force = MemoryForce(rule, source)
    out = fem.petsc.create_vector(fem.form(ufl.inner(M, strain(ufl.TestFunction(u.function_space))) * rule.dx))
    force(M, out)
    want = fem.petsc.assemble_vector(fem.form(ufl.inner(M, strain(ufl.TestFunction(u.function_space))) * rule.dx))
    want.ghostUpdate(addv=fem.petsc.PETSc.InsertMode.ADD, mode=fem.petsc.PETSc.ScatterMode.REVERSE)
    assert np.allclose(out.array_r, want.array_r, rtol=1e-12, atol=1e-12 * np.abs(want.array_r).max())


def test_a_remembered_source_gives_the_same_numbers_and_never_a_stale_one(comm):
    """remember(): H, base + scale H and Phi (unit()) equal the plain source's to round-off, for the same values
    and after u or zeta changed (a kept H of old values is never returned); H itself is zeta Phi exactly."""
    _, u, zeta, rule = _box(comm, 1)
    integrand = MemoryIntegrand(60.0, *lame(100.0, 0.3, "plane_strain"))
    plain = MemorySource(rule, u, zeta, integrand)
    kept = MemorySource(rule, u, zeta, integrand, keep=1)
    kept.remember()
    base = np.random.default_rng(2).standard_normal(plain.size_q * 9)

    def agree():
        ref = plain()
        scale = np.abs(ref).max()
        for _ in range(2):  # computed, then found
            assert np.array_equal(kept(), ref)  # H at scale 1: the law's own product zeta Phi
            got, want = kept(base=base, scale=0.3), plain(base=base, scale=0.3)
            assert np.abs(got - want).max() <= 1e-14 * scale
        unit = kept.unit().reshape(-1, 9) * kept.zeta_at_points()[:, None]
        assert np.array_equal(unit.ravel(), ref)

    agree()
    zeta.x.array[:] *= 0.7  # zeta changed, u not
    agree()
    u.x.array[:] *= 1.3  # u changed, zeta not
    agree()
    ez = np.random.default_rng(3).standard_normal(zeta.x.array.size)  # another array of zeta's space at the points
    zeta.x.array[:], keep_values = ez, zeta.x.array.copy()
    at = plain.zeta_at_points()
    zeta.x.array[:] = keep_values
    assert np.array_equal(kept.zeta_at_points(ez), at)


@pytest.mark.parametrize("keep", [1, 2])
def test_a_new_strain_is_made_after_the_oldest_kept_one_is_let_go(comm, keep):
    """strain(): of the field's own values, at most ``keep`` strains are held while a new one is made (the oldest
    is dropped first: at 311,469 dofs in 3-D each is 27 MiB); the strains of every values kept still equal the
    product, and an array that is not the field's (u_prev of the extrapolation) drops none."""
    import gc
    import weakref

    _, u, zeta, rule = _box(comm, 1)
    src = MemorySource(rule, u, zeta, MemoryIntegrand(60.0, *lame(100.0, 0.3, "plane_strain")), keep=keep)
    E = src.strain_operator
    alive_at_product = []
    made = []

    class Counting:
        """E's products, counting the source's kept strains still alive when each is made."""

        def __matmul__(self, v):
            gc.collect()
            alive_at_product.append(sum(r() is not None for r in made))
            out = E @ v
            made.append(weakref.ref(out if out.base is None else out.base))  # the memory's owner
            return out

    src.strain_operator = Counting()
    values = [u.x.array.copy() * s for s in (1.0, 1.5, 0.5, 2.0)]
    for v in values:
        u.x.array[:] = v
        eps = src.strain()
        assert np.array_equal(eps, (E @ v).reshape(eps.shape))
        del eps
    assert alive_at_product == [min(i, keep - 1) for i in range(len(values))]
    other = values[0] * 3.0  # not the field's own values: computed, nothing dropped
    before = len(src._cache)
    assert np.array_equal(src.strain(other), (E @ other).reshape(len(src.pairs), -1))
    assert len(src._cache) == before
    for v, (kept_u, kept_eps) in zip(values[::-1], src._cache):  # newest first
        assert np.array_equal(kept_u, v) and np.array_equal(kept_eps, (E @ v).reshape(kept_eps.shape))
