"""solver/physics/cell_blocks.py: a linear form assembled a block of cells at a time gives the one-form assembly's
vector bit for bit (each entry's contributions in the same order), serially and on 2 ranks; forms it cannot split
stay one form."""

import numpy as np
import pytest
import ufl
from dolfinx import fem, mesh
from dolfinx.fem import petsc as fpetsc
from mpi4py import MPI

from solver.config import DamageConfig
from solver.physics.cell_blocks import CellBlockForm
from solver.physics.material import strain
from solver.solvers.damage_step import make_damage


def _fields(comm):
    m = mesh.create_unit_cube(comm, 5, 4, 3)
    u = fem.Function(fem.VectorFunctionSpace(m, ("CG", 1)))
    z = fem.Function(fem.FunctionSpace(m, ("CG", 1)))
    rng = np.random.default_rng(comm.rank)
    u.x.array[:] = rng.standard_normal(u.x.array.size)
    z.x.array[:] = rng.random(z.x.array.size)
    u.x.scatter_forward()
    z.x.scatter_forward()
    return m, u, z


def _assembled(form, assemble) -> np.ndarray:
    b = fpetsc.create_vector(fem.form(form))
    assemble(b)
    return b.array.copy()  # the local array before any ghost update: each rank's own sums


@pytest.mark.parametrize("block", [1, 7, 100, 10**6])
def test_blocks_give_the_one_form_vector_bit_for_bit(comm, block):
    """A damage-like source (two integrals, one with a quadrature degree, a max in the integrand) in blocks of
    1, 7, 100 cells and in one block: the vector of the one compiled form, entry for entry."""
    m, u, z = _fields(comm)
    xi = ufl.TestFunction(z.function_space)
    e = strain(u)
    L = (z + 0.02 * ufl.max_value(ufl.inner(e, e) - z, 0.0)) * xi * ufl.dx(metadata={"quadrature_degree": 2}) \
        - 0.3 * z * xi * ufl.dx
    whole = _assembled(L, lambda b: fpetsc.assemble_vector(b, fem.form(L)))
    blocks = CellBlockForm(m, L, block)
    owned = m.topology.index_map(3).size_local
    expected = comm.allreduce(-(-owned // block), op=MPI.MAX)
    assert len(blocks.forms) == (1 if expected <= 1 else expected)
    assert np.array_equal(_assembled(L, blocks.assemble), whole)


def test_a_form_with_a_facet_integral_stays_one_form(comm):
    m, u, z = _fields(comm)
    xi = ufl.TestFunction(z.function_space)
    L = z * xi * ufl.dx + z * xi * ufl.ds
    blocks = CellBlockForm(m, L, 5)
    assert len(blocks.forms) == 1
    assert np.array_equal(_assembled(L, blocks.assemble), _assembled(L, lambda b: fpetsc.assemble_vector(b, fem.form(L))))


@pytest.mark.parametrize("scheme", ["explicit", "semi_implicit", "cnab2"])
def test_the_damage_step_in_blocks_is_the_one_form_step(comm, scheme, monkeypatch):
    """Every damage scheme's step (the source assembled in blocks of 11 cells) gives zeta bit for bit as with its
    source assembled as one form."""
    import solver.physics.cell_blocks as cell_blocks

    cfg = DamageConfig(enabled=True, kappa=1e-2, lambda1=1e-2, lambda2=10.0, lambda3=0.0, zeta_star=0.01)
    results = []
    whole = cell_blocks.BLOCK  # more than the mesh's cells: one form
    m, u, _ = _fields(comm)
    u.interpolate(lambda x: np.vstack([0.1 * x[0] * x[1], np.sin(x[2]) * 0.05, 0.08 * x[0] ** 2]))
    Z = fem.FunctionSpace(m, ("CG", 1))
    for block in (whole, 11):
        monkeypatch.setattr(cell_blocks, "BLOCK", block)
        damage = make_damage(scheme, Z, u, cfg, 0.02, 2)
        assert len(damage.rhs_blocks.forms) == (1 if block == whole else
                                                comm.allreduce(-(-m.topology.index_map(3).size_local // 11),
                                                               op=MPI.MAX))
        for _ in range(3):
            damage.step()
        if scheme == "cnab2":
            damage.correct_first_step()
        results.append(damage.zeta.x.array.copy())
    assert np.array_equal(results[0], results[1])
