# ---
# jupyter:
#   jupytext:
#     formats: py:percent
#     text_representation:
#       extension: .py
#       format_name: percent
# ---

# %% [markdown]
# # A scene of one's own, built in Python
#
# A plate with a hole, meshed with gmsh from Python, held at its top, pulled sideways and down on its right side
# by a traction that grows in time, and resting on a soft foundation below. The mesh's physical groups name the
# boundary parts; the scene is a TOML-shaped dict, validated as a file is.

# %%
import os
from pathlib import Path

import gmsh
from mpi4py import MPI

from solver import api

ROOT = Path(__file__).resolve().parents[1] if "__file__" in globals() else Path.cwd()
OUT = Path(os.environ.get("DEMO_OUTPUT", ROOT / "results" / "demos"))
OUT.mkdir(parents=True, exist_ok=True)
MSH = OUT / "plate_with_hole.msh"

# %% [markdown]
# ## The mesh
#
# A 2 × 1 plate minus a disk of radius 0.2. Every boundary curve goes into a physical group by where it lies;
# the surface goes into a group too (dolfinx reads the cells of the physical surfaces). Rank 0 writes the file.

# %%
if MPI.COMM_WORLD.rank == 0:
    gmsh.initialize()
    gmsh.option.setNumber("General.Terminal", 0)
    occ = gmsh.model.occ
    plate, _ = occ.cut([(2, occ.addRectangle(0, 0, 0, 2, 1))], [(2, occ.addDisk(1, 0.5, 0, 0.2, 0.2))])
    occ.synchronize()
    groups = {"top": [], "bottom": [], "right": [], "free": []}
    for _, curve in gmsh.model.getBoundary(plate, oriented=False):
        x, y, _ = occ.getCenterOfMass(1, curve)
        name = "top" if abs(y - 1) < 1e-9 else "bottom" if abs(y) < 1e-9 else "right" if abs(x - 2) < 1e-9 else "free"
        groups[name].append(curve)
    for name, curves in groups.items():
        gmsh.model.setPhysicalName(1, gmsh.model.addPhysicalGroup(1, curves), name)
    gmsh.model.setPhysicalName(2, gmsh.model.addPhysicalGroup(2, [plate[0][1]]), "domain")
    gmsh.option.setNumber("Mesh.MeshSizeMax", 0.08)
    gmsh.option.setNumber("Mesh.MshFileVersion", 4.1)
    gmsh.model.mesh.generate(2)
    gmsh.write(str(MSH))
    gmsh.finalize()
MPI.COMM_WORLD.barrier()

# %% [markdown]
# ## The scene
#
# Parts are `[boundary.NAME]` tables named after the physical groups; the right side's traction is a table of
# rows `[t, f_x, f_y]`, linear in between; the foundation is softer than the paper's (μ = 1e-3) and the material is
# in plane strain. Every other key keeps the paper's value.

# %%
cfg = api.scene({
    "mesh": {"kind": "gmsh", "file": str(MSH)},
    "boundary": {
        "top": {"role": "clamped"},
        "right": {"role": "traction", "traction": [[0.0, 0.0, 0.0], [1.0, 20.0, -10.0]]},
        "bottom": {"role": "contact", "gap": 0.0, "mu": 1e-3},
    },
    "material": {"model": "plane_strain"},
    "time": {"T": 1.0, "k": 0.05},
})
res = api.run(cfg, OUT / "plate_with_hole", overwrite=True)
print(f"{len(res.points)} nodes; at t = 1: contact force {res.series['contact_force'][-1]:.4g}, "
      f"contact length {res.series['contact_length'][-1]:.3g}, min damage {res.series['zeta_min'][-1]:.5f}")
print("reaction of the top:", {c: round(res.series[c][-1], 4) for c in res.columns if c.startswith("reaction_")})

# %% [markdown]
# The results directory (`solution.xdmf`, `timeseries.csv`, `config.toml`) opens in ParaView like any run's;
# `config.toml` there is the resolved scene, so `python -m solver run results/demos/plate_with_hole/config.toml`
# runs it again from the command line.
