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
# (`meshes/hertz3d.py`) finely near the contact (h = 0.03, about 6 edges across the contact radius) and coarsely far
# from it, with P2 displacements. Hertz's theory, from the total force P:
#
#     a³ = 3 P R / (4 E*),    p₀ = 3 P / (2 π a²),    E* = E / (1 − ν²).
#
# P is the contact force (four times the quarter's, the reaction of the pushed face as a check); the contact
# radius a is read from the contact force's distribution, a² = (5/2) ∫ p r² ds / ∫ p ds (Hertz's
# p₀ √(1 − r²/a²) has exactly this second moment); the peak pressure is the reported pressure's maximum, and, beside
# it, the law's pressure at the quadrature points averaged near the axis against Hertz's same average. The
# compliance μ = 1e-5 lets the body into the sphere by μ p ~ 1e-6, 1e-4 of the approach: rigid contact for
# Hertz's formulas. Why P2 (docs/guide/contact.md, `benchmarks/results/hertz_sphere.md`): the law acts at the
# contact term's quadrature points with the sphere's exact gap, which a P1 facet cannot follow closer than about
# h²/(8R) (1.4e-5 at h = 0.015), 20 times the penetration μ p₀ the law allows; the pressure at the points then
# scatters from point to point and the vertex means about Hertz's profile by a few per cent (P1, h = 0.015: peak
# +3.8%). A P2 facet follows the sphere's curvature to within the law's penetration, and the pressure is smooth.
# Only the first level (t = 0) is solved: the elastic contact problem.

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
from solver.physics.quadrature import ContactRule, facet_type
from solver.run.model import build_model
from solver.run.stepper import Stepper

ROOT = Path(__file__).resolve().parents[1] if "__file__" in globals() else Path.cwd()
OUT = Path(os.environ.get("DEMO_OUTPUT", ROOT / "results" / "demos"))
OUT.mkdir(parents=True, exist_ok=True)
H = float(os.environ.get("HERTZ_H", "0.03"))  # the mesh size at the contact (the tests take a coarser one)
DEGREE = int(os.environ.get("HERTZ_DEGREE", "2"))  # P2 displacements
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
    print(mesher.write(MSH, H, size=2.0))
MPI.COMM_WORLD.barrier()

# %% [markdown]
# ## The scene and its first level

# %%
scene = {
    "mesh": {"kind": "gmsh", "file": str(MSH)},
    "material": {"E": E, "nu": NU, "model": "3d"}, "discretization": {"u_degree": DEGREE},
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
rule = ContactRule.of(model.cfg)  # the contact term's rule (solver.contact_points, its degree)
x = ufl.SpatialCoordinate(geo.mesh)
p = compliance(penetration(u, ufl.FacetNormal(geo.mesh), gap_function(part, geo, rule)), part)
ds = geo.ds(geo.tags[part.name], metadata=rule.metadata(facet_type(geo.mesh)))
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

# %% [markdown]
# ## The pressure against Hertz's profile
#
# The reported pressure at the vertices of the contact face (the lumped-mass mean of the law's values at the
# quadrature points, `contact.xdmf`'s `contact_pressure`) against p₀ (1 − r²/a²)^{1/2}, and as a map of the face.

# %%
traces = model.mech.diagnostics.traces
on = traces.on[traces.on < traces.n_local]
gathered = MPI.COMM_WORLD.gather((traces.x[on], traces.pressure.x.array[on]), root=0)
if MPI.COMM_WORLD.rank == 0:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    from matplotlib.tri import Triangulation

    xyz = np.concatenate([g[0] for g in gathered])
    pv = np.concatenate([g[1] for g in gathered])
    rv = np.hypot(xyz[:, 0], xyz[:, 1])
    fig, (left, right) = plt.subplots(1, 2, figsize=(10, 4))
    rr = np.linspace(0.0, a_hertz, 400)
    left.plot(rv, pv, ".", ms=4, color="C0", label="reported pressure at the vertices")
    left.plot(rr, p0_hertz * np.sqrt(1.0 - (rr / a_hertz) ** 2), "-", color="C3", label="Hertz, p₀ (1 − r²/a²)^½")
    left.axvline(a, color="C2", ls=":", label=f"contact radius from ∫ p r² ds: {a:.4g}")
    left.set(xlim=(0.0, 1.6 * a_hertz), xlabel="distance r from the axis (model units)",
             ylabel="contact pressure (model units)", title=f"P{DEGREE}, h = {H} at the contact")
    left.legend(fontsize=8, loc="lower left")
    keep = rv < 2.5 * a_hertz
    tri = Triangulation(xyz[keep, 0], xyz[keep, 1])
    shade = right.tripcolor(tri, pv[keep], shading="gouraud", cmap="viridis")
    fig.colorbar(shade, ax=right, label="contact pressure (model units)")
    phi = np.linspace(0.0, np.pi / 2, 100)
    right.plot(a_hertz * np.cos(phi), a_hertz * np.sin(phi), "--", color="C3", lw=1.2, label="Hertz's contact radius")
    right.set(aspect="equal", xlim=(0.0, 1.5 * a_hertz), ylim=(0.0, 1.5 * a_hertz), xlabel="x (model units)",
              ylabel="y (model units)", title="the contact face z = 0 (a quarter)")
    right.legend(fontsize=8, loc="upper right")
    fig.tight_layout()
    fig.savefig(OUT / "hertz3d_pressure.png", dpi=100)
