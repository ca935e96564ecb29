# ---
# jupyter:
#   jupytext:
#     formats: py:percent
#     text_representation:
#       extension: .py
#       format_name: percent
# ---

# %% [markdown]
# # The paper's Example 1 from Python
#
# A unit square, clamped on the left, pushed by the traction (−10, −10) on the right and pressed onto a nearly
# rigid foundation below (normal compliance, μ = 1e-10), with long memory and damage: Example 1 of Campo,
# Fernández and Rodríguez-Arós (2008), `configs/example1.toml`. This runs the same scene as
# `python -m solver run configs/example1.toml` (the tests check that the two agree to 1e-12) and looks at what it
# computed, without a results directory.
#
# Run it with the project's Python from the repository's root: `.venv/bin/python demos/example1.py`.

# %%
import os
from pathlib import Path

from solver import api

ROOT = Path(__file__).resolve().parents[1] if "__file__" in globals() else Path.cwd()
OUT = Path(os.environ.get("DEMO_OUTPUT", ROOT / "results" / "demos"))
OUT.mkdir(parents=True, exist_ok=True)

# %% [markdown]
# ## The scene
#
# `api.load` reads and validates the scene file; every key not in the file has the paper's value
# ([scene reference](../reference/scene.md)).

# %%
cfg = api.load(ROOT / "configs" / "example1.toml")
print(cfg.mesh.nx, "x", cfg.mesh.ny, "cells;", cfg.time.steps, "steps of k =", cfg.time.k)
print("parts:", [(b.name, b.role) for b in cfg.boundaries])

# %% [markdown]
# ## The run, in memory
#
# `api.run(cfg)` solves every level and returns the time series (one numpy array per column of
# `timeseries.csv`) and the final fields at the mesh nodes.

# %%
res = api.run(cfg)
print("columns:", ", ".join(res.columns[:10]), "...")
print(f"t = {res.series['t'][-1]:g}: contact force {res.series['contact_force'][-1]:.6g}, "
      f"min damage {res.series['zeta_min'][-1]:.6g}")

# %% [markdown]
# The damage ζ decreases from 1 (undamaged) where the strain is large; its minimum over the body and the contact
# force are the two quantities the paper discusses.

# %%
import matplotlib  # noqa: E402

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402

fig, (a, b) = plt.subplots(1, 2, figsize=(9, 3.2))
a.plot(res.series["t"], res.series["zeta_min"])
a.set(xlabel="t", ylabel="min ζ", title="damage")
b.plot(res.series["t"], res.series["contact_force"])
b.set(xlabel="t", ylabel="∫ p ds", title="contact force")
fig.tight_layout()
fig.savefig(OUT / "example1_series.png", dpi=100)

# %% [markdown]
# ## The final fields
#
# `res.fields` holds the displacement (nodes × 2) and the damage (one value a node) at `res.points`; the live
# dolfinx objects are in `res.model` (`res.model.u`, `res.model.zeta`) for post-processing with UFL.

# %%
u, zeta = res.fields["displacement"], res.fields["damage"]
worst = zeta.argmin()
print(f"most damaged node at {res.points[worst]}: ζ = {zeta[worst]:.6g}, |u| = {abs(u[worst]).max():.3g}")
fig, ax = plt.subplots(figsize=(4, 3.6))
tc = ax.tricontourf(res.points[:, 0], res.points[:, 1], zeta, levels=20)
fig.colorbar(tc, label="ζ at t = 1")
ax.set_aspect("equal")
fig.savefig(OUT / "example1_damage.png", dpi=100)
