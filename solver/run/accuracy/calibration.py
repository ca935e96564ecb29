"""The estimator's constant C on the scene itself: error / eta from a mesh and its uniform refinement at t = 0
(docs/guide/accuracy.md, "Calibration constants").

On a mesh M and its uniform refinement M' (nested, same degree: u_M is exactly a function on M'), the difference
D = ||eps(u_M - u_M')|| and the indicators' ratio rho = eta_M' / eta_M give M's error. Galerkin orthogonality (exact
for the elastic part in its energy norm, to which ||eps(.)|| is close) makes the errors and D a right triangle,
e_M^2 = D^2 + e_M'^2, and with e_M' = rho e_M (the indicator is reliable and efficient, so it falls as the error
does) e_M = D / sqrt(1 - rho^2). C = SAFETY e_M / eta_M replaces the stored constant (measured on Example 1 only,
and rounded up): sharper where the scene is like Example 1, larger where it is not. On Example 1 (P2, 993 cells)
this gives C = 1.63e-3 before SAFETY, where `study estimator` measured 1.55-1.74e-3 against the exact solution;
the triangle inequality alone (e_M <= D / (1 - rho)) gave 2.75e-3. One solve on M', started from u_M.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

from dolfinx import fem
from mpi4py import MPI

from solver.mesh.adapt import refine_uniformly
from solver.mesh.transfer import interpolation_matrix
from solver.run.model import Model

from .solves import SpaceProbe
from .time_error import norms

SAFETY = 1.1  # on the calibrated C
RHO_MAX = 0.9  # an indicator falling less under a uniform refinement: no extrapolation, the stored C is kept


@dataclass(frozen=True)
class Calibration:
    """What the calibration measured and the constant it gives."""

    cells: int  # M's cells
    indicator: float  # eta on M
    finer_indicator: float  # eta on M'
    difference: float  # ||eps(u_M - u_M')||
    stored: float  # the stored constant
    C: float  # the constant used

    @property
    def ratio(self) -> float:
        return self.finer_indicator / self.indicator if self.indicator > 0 else 0.0

    def summary(self) -> dict:
        """As plan.json writes it."""
        return {"cells": self.cells, "eta": self.indicator, "eta_refined": self.finer_indicator,
                "difference": self.difference, "C_stored": self.stored, "C": self.C}


def strain_difference(coarse: Model, fine: Model, comm: MPI.Comm) -> float:
    """||eps(u_coarse - u_fine)||, u_coarse interpolated on the fine (nested) mesh's space of the same degree."""
    V = fine.u.function_space
    bs, owned = V.dofmap.index_map_bs, V.dofmap.index_map.size_local
    P = interpolation_matrix(coarse.u.function_space, V.tabulate_dof_coordinates()[:owned, :2])
    d = fem.Function(V)
    d.x.array[:owned * bs] = (P @ coarse.u.x.array.reshape(-1, bs)).ravel() - fine.u.x.array[:owned * bs]
    d.x.scatter_forward()
    return norms(fine, comm)[0](d.x.array)


def calibrate(probe: SpaceProbe, degree: int, comm: MPI.Comm, model: Model, indicator: float,
              stored: float) -> Calibration:
    """C from ``model`` (a level-0 solve of ``probe`` on M, its indicator ``indicator``) and a solve on M's uniform
    refinement. Collective."""
    finer = probe.solve(degree, comm, refine_uniformly(model.geo), model)
    try:
        D = strain_difference(model, finer.model, comm)
    except ValueError:  # a point off this process's part of M (collective: every process raises in norms' stead)
        D = math.nan
    if not comm.allreduce(math.isfinite(D), op=MPI.LAND):
        return Calibration(model.geo.num_cells(), indicator, finer.indicator, math.nan, stored, stored)
    rho = finer.indicator / indicator if indicator > 0 else 1.0
    C = stored if (rho >= RHO_MAX or indicator <= 0) else SAFETY * D / (math.sqrt(1.0 - rho**2) * indicator)
    return Calibration(model.geo.num_cells(), indicator, finer.indicator, D, stored, C)
