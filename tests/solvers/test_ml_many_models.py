"""Many iterative 3-D models in one process (issue 30): Trilinos ML's uncoupled aggregation crashed at the ninth."""

import os
import subprocess
import sys

import pytest
from conftest import ROOT
from petsc4py import PETSc

LOOP = """
import sys
from mpi4py import MPI
from solver.config import load
from solver.io.results import run
from solver.run.model import build_model
for i in range(12):
    cfg = load("configs/example1_3d.toml", ["mesh.nx=3", "mesh.ny=3", "mesh.nz=3", "time.k=0.05", "time.T=0.1",
                                            "output.xdmf=false", "solver.linear='iterative'",
                                            "solver.petsc_options.mech_pc_type='ml'"])
    run(build_model(cfg, MPI.COMM_WORLD), None)
print("built", i + 1)
"""


@pytest.mark.serial  # starts its own process
@pytest.mark.skipif(not PETSc.Sys.hasExternalPackage("ml"), reason="PETSc without Trilinos ML")
def test_twelve_iterative_3d_models_in_one_process():
    """With ML's default uncoupled aggregation the ninth model's preconditioner set-up died with SIGSEGV (PETSc exit
    59); the iterative path's defaults set MIS aggregation for ML too (linear.AMG), so ML chosen by
    ``mech_pc_type = "ml"`` alone gets it. A process of its own, so a crash is a failure here, not the end of the
    test run."""
    res = subprocess.run([sys.executable, "-c", LOOP], cwd=ROOT, env=dict(os.environ), capture_output=True, text=True,
                         timeout=900)
    assert res.returncode == 0, (res.returncode, res.stderr[-2000:])
    assert res.stdout.strip().endswith("built 12")
