"""Calibration constants of accuracy on demand: measured, not derived (figures and provenance in
docs/guide/accuracy.md, "Calibration constants")."""

from __future__ import annotations

# C = error / indicator of the residual estimator times 2 mu (the indicator is a stress, the error a strain), per
# displacement degree: the largest values measured on Example 1, rounded up
C_TIMES_2MU = {1: 4.0e-3 * 100.0 / 1.3, 2: 1.8e-3 * 100.0 / 1.3}
# error ~ dofs^-rate on meshes adapted by Dörfler marking, per displacement degree
ADAPTED_RATE = {1: 0.49, 2: 1.02}
# a time step's cost per displacement dof, per degree, relative to P1
COST_PER_DOF = {1: 1.0, 2: 1.13}

# on tetrahedra (scripts/estimator_3d.py, 3-D Example 1 at t = 0; docs/guide/accuracy.md, "3-D"): the measured C
# stayed below the 2-D values, which are kept; the adapted rates are lower (dofs ~ h^-3): P1 the 2-D rate times 2/3
# (uniform meshes measured 0.36), P2 measured 0.54-0.66 over two Dörfler steps
C_TIMES_2MU_3D = dict(C_TIMES_2MU)
ADAPTED_RATE_3D = {1: 0.33, 2: 0.6}


def c_times_2mu(dim: int) -> dict[int, float]:
    """C_TIMES_2MU of the mesh's dimension (triangles: 2, tetrahedra: 3)."""
    return C_TIMES_2MU if dim == 2 else C_TIMES_2MU_3D


def adapted_rate(dim: int) -> dict[int, float]:
    """ADAPTED_RATE of the mesh's dimension (triangles: 2, tetrahedra: 3)."""
    return ADAPTED_RATE if dim == 2 else ADAPTED_RATE_3D
