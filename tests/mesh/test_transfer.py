"""solver/mesh/transfer.py: locating points in a mesh's cells."""

import numpy as np
import pytest
from dolfinx import mesh
from mpi4py import MPI

from solver.mesh.transfer import locate

pytestmark = pytest.mark.serial  # locate works on this process's cells


def _square(n: int):
    return mesh.create_unit_square(MPI.COMM_SELF, n, n)


def test_a_point_off_the_boundary_by_round_off_is_in_its_nearest_cell():
    """An adapted mesh's node can come out one ulp outside the square (x = 1 + 2.2e-16, as a planned mesh
    met it): dolfinx's collision test misses it once the cells are small (1/256 here), and locate puts it in the cell
    that touches it, with reference coordinates in the triangle up to round-off."""
    points = np.array([[1.0000000000000002, 0.003906250000000001], [1.0000000000000002, 0.6], [0.5, 0.5]])
    cells, _, ref = locate(_square(256), points)
    assert np.all(cells >= 0)
    assert np.all(ref >= -1e-12) and np.all(ref.sum(axis=1) <= 1 + 1e-12)


@pytest.mark.parametrize("point", [[0.375, -1e-6], [1.5, 0.5], [1.0 + 1e-10, 0.5]])
def test_a_point_outside_the_mesh_is_refused(point):
    with pytest.raises(ValueError, match="outside the mesh"):
        locate(_square(256), np.array([point]))


def test_on_tetrahedra_a_quadratic_and_its_gradient_are_carried_exactly():
    """P2 on a box holds a quadratic exactly: its values and gradients at points anywhere in the cube (the dofs of
    a nested finer mesh included) come out exact."""
    from dolfinx import fem

    from solver.mesh.transfer import gradient_matrices, interpolation_matrix

    cube = mesh.create_unit_cube(MPI.COMM_SELF, 2, 3, 2)
    V = fem.FunctionSpace(cube, ("Lagrange", 2))
    f = fem.Function(V)
    f.interpolate(lambda x: x[0] ** 2 + 2 * x[1] * x[2] - x[2])
    pts = np.random.default_rng(0).random((50, 3))
    assert interpolation_matrix(V, pts) @ f.x.array == pytest.approx(pts[:, 0] ** 2 + 2 * pts[:, 1] * pts[:, 2]
                                                                     - pts[:, 2], abs=1e-12)
    dx, dy, dz = (D @ f.x.array for D in gradient_matrices(V, pts))
    assert dx == pytest.approx(2 * pts[:, 0], abs=1e-11) and dy == pytest.approx(2 * pts[:, 2], abs=1e-11)
    assert dz == pytest.approx(2 * pts[:, 1] - 1, abs=1e-11)
