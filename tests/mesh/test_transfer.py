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
