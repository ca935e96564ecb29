"""The residual estimate of the gmsh column with its cells below z = 0.3 refined once (P1, t = 0), to compare
serially with `mpirun -n 2`: the same cells and the same eta to round-off (docs/guide/accuracy.md, 3-D)."""

import numpy as np
from dolfinx import mesh as dmesh
from mpi4py import MPI

from solver.config import load
from solver.mesh.adapt import refine
from solver.physics.estimator import estimator_for
from solver.run.model import build_model
from solver.run.stepper import Stepper

comm = MPI.COMM_WORLD
cfg = load("configs/column3d.toml", ["discretization.u_degree=1"])
model = build_model(cfg, comm)
geo = model.geo
n = geo.mesh.topology.index_map(3).size_local
mid = dmesh.compute_midpoints(geo.mesh, 3, np.arange(n, dtype=np.int32))
geo = refine(geo, np.flatnonzero(mid[:, 2] < 0.3))
model = build_model(cfg, comm, geo)
Stepper(model).step(0)
est = estimator_for(model)
e = est.total(est.cells())
if comm.rank == 0:
    print("cells", geo.num_cells(), "eta", repr(e))
