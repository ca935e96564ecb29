# ---
# jupyter:
#   jupytext:
#     formats: py:percent
#     text_representation:
#       extension: .py
#       format_name: percent
# ---

# %% [markdown]
# # Hertz's sphere in 3-D
#
# A rigid sphere of radius R = 2 (the analytic `sphere` obstacle) pressed 0.015 into an elastic block
# (E = 1, ν = 0.3). A quarter of the block, (0, 2)³, with the symmetry planes x = 0 and y = 0, meshed with gmsh
# (`meshes/hertz3d.py`) finely near the contact and coarsely far from it. Hertz's theory, from the total force P:
#
#     a³ = 3 P R / (4 E*),    p₀ = 3 P / (2 π a²),    E* = E / (1 − ν²).
#
# P is the contact force (four times the quarter's, the reaction of the pushed face as a check); the contact
# radius a is read from the contact force's distribution, a² = (5/2) ∫ p r² ds / ∫ p ds (Hertz's
# p₀ √(1 − r²/a²) has exactly this second moment); the peak pressure is the reported pressure's maximum, and, beside
# it, the law's pressure at the quadrature points averaged near the axis against Hertz's same average. The
# compliance μ = 1e-5 lets the body into the sphere by μ p ~ 1e-6, 1e-4 of the approach: rigid contact for
# Hertz's formulas. Only the first level (t = 0) is solved: the elastic contact problem.

# %%
import importlib.util
import math
import os
from pathlib import Path

import numpy as np
import ufl
from dolfinx import fem
from mpi4py import MPI

from solver.config import from_dict
from solver.physics.contact import compliance, gap_function, penetration
from solver.run.model import build_model
from solver.run.stepper import Stepper

ROOT = Path(__file__).resolve().parents[1] if "__file__" in globals() else Path.cwd()
OUT = Path(os.environ.get("DEMO_OUTPUT", ROOT / "results" / "demos"))
OUT.mkdir(parents=True, exist_ok=True)
H = float(os.environ.get("HERTZ_H", "0.015"))  # the mesh size at the contact (the tests take a coarser one)
MSH = OUT / "hertz3d.msh"
R, DEPTH, E, NU, MU = 2.0, 0.015, 1.0, 0.3, 1e-5

# %% [markdown]
# ## The mesh
#
# `meshes/hertz3d.py` names the faces by physical groups: `bottom` (z = 0, in contact), `top` (pushed down),
# `sym_x`, `sym_y` (the symmetry planes) and `free`. Rank 0 writes the file.

# %%
if MPI.COMM_WORLD.rank == 0:
    spec = importlib.util.spec_from_file_location("hertz3d_mesh", ROOT / "meshes" / "hertz3d.py")
    mesher = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mesher)
    print(mesher.write(MSH, H, near=0.3, far=0.4, size=2.0))
MPI.COMM_WORLD.barrier()

# %% [markdown]
# ## The scene and its first level

# %%
scene = {
    "mesh": {"kind": "gmsh", "file": str(MSH)},
    "material": {"E": E, "nu": NU, "model": "3d"},
    "memory": {"kernel": "none"}, "damage": {"enabled": False}, "time": {"T": 1.0, "k": 1.0},
    "boundary": {
        "sym_x": {"role": "displacement", "displacement": [0.0, "free", "free"]},
        "sym_y": {"role": "displacement", "displacement": ["free", 0.0, "free"]},
        "top": {"role": "displacement", "displacement": ["free", "free", -DEPTH]},
        "bottom": {"role": "contact", "mu": MU,
                   "obstacle": {"shape": "sphere", "centre": [0.0, 0.0, -R], "radius": R}},
    },
}
model = build_model(from_dict(scene), MPI.COMM_WORLD)
row = Stepper(model).step(0)

# %% [markdown]
# ## Against Hertz
#
# The contact force's second moment about the axis, ∫ p r² ds, at the contact term's own quadrature points.

# %%
geo, u = model.geo, model.u
part = next(b for b in model.cfg.boundaries if b.role == "contact")
degree = model.mech.contact.jacobian_ufl.integrals()[0].metadata()["quadrature_degree"]
x = ufl.SpatialCoordinate(geo.mesh)
p = compliance(penetration(u, ufl.FacetNormal(geo.mesh), gap_function(part, geo, degree)), part)
ds = geo.ds(geo.tags[part.name], metadata={"quadrature_degree": degree})
r2 = x[0] ** 2 + x[1] ** 2


def integral(f):
    return geo.comm.allreduce(fem.assemble_scalar(fem.form(f * ds)), op=MPI.SUM)


moment = integral(p * r2)

P = 4.0 * row["contact_force"]
a = math.sqrt(2.5 * moment / row["contact_force"])
E_star = E / (1.0 - NU ** 2)
a_hertz = (3.0 * P * R / (4.0 * E_star)) ** (1.0 / 3.0)
p0_hertz = 3.0 * P / (2.0 * math.pi * a_hertz ** 2)
peak = row["peak_pressure"]
# the law's pressure near the axis, weighted by w = (1 - r²/rho²)_+ (rho = a/4), against Hertz's for the same w
rho = 0.25 * a_hertz
w = ufl.max_value(1.0 - r2 / rho ** 2, 0.0)
central = integral(p * w) / integral(w)
t = np.linspace(0.0, 1.0, 20001)  # r = rho t: Hertz's mean of sqrt(1 - r²/a²) under w, by the trapezoid rule
weight = (1.0 - t ** 2) * t
central_hertz = p0_hertz * np.trapz(np.sqrt(1.0 - (rho * t / a_hertz) ** 2) * weight, t) / np.trapz(weight, t)
a_area = math.sqrt(4.0 * row["contact_length"] / math.pi)
if MPI.COMM_WORLD.rank == 0:
    print(f"h = {H}: {row['newton_iterations']} Newton iterations")
    print(f"P = {P:.5g} (reaction of the top: {4.0 * abs(row['reaction_top_z']):.5g})")
    print(f"contact radius a = {a:.4g}, Hertz {a_hertz:.4g}: {a / a_hertz - 1.0:+.2%}")
    print(f"peak pressure {peak:.4g}, Hertz p0 {p0_hertz:.4g}: {peak / p0_hertz - 1.0:+.2%}")
    print(f"pressure near the axis (the law's, weighted by (1 - r²/rho²)_+, rho = a/4) {central:.4g}, Hertz "
          f"{central_hertz:.4g}: {central / central_hertz - 1.0:+.2%}")
    print(f"(the radius of the area where the quadrature points penetrate: {a_area:.4g}, {a_area / a_hertz - 1.0:+.2%})")
