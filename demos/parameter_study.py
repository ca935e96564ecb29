# ---
# jupyter:
#   jupytext:
#     formats: py:percent
#     text_representation:
#       extension: .py
#       format_name: percent
# ---

# %% [markdown]
# # A parameter study in a loop
#
# How does the damage depend on the damage source's growth coefficient λ₂? A study is a loop over
# `Config.replace`: each change is validated as a scene file is (a wrong value is the same one-line error), and
# each run returns arrays. No strings, no results directories.

# %%
import os
from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402

from solver import api  # noqa: E402

ROOT = Path(__file__).resolve().parents[1] if "__file__" in globals() else Path.cwd()
OUT = Path(os.environ.get("DEMO_OUTPUT", ROOT / "results" / "demos"))
OUT.mkdir(parents=True, exist_ok=True)

# %% [markdown]
# Example 1 on a coarser mesh and step, so that the whole study takes seconds.

# %%
base = api.load(ROOT / "configs" / "example1.toml").replace({"mesh": {"nx": 8, "ny": 8}, "time": {"k": 0.02}})

results = {}
for lambda2 in (2.0, 5.0, 10.0, 20.0):
    cfg = base.replace({"damage": {"lambda2": lambda2}})
    results[lambda2] = api.run(cfg).series
    print(f"lambda2 = {lambda2:5g}: min damage at t = 1: {results[lambda2]['zeta_min'][-1]:.5f}")

# %%
fig, ax = plt.subplots(figsize=(5, 3.4))
for lambda2, s in results.items():
    ax.plot(s["t"], s["zeta_min"], label=f"λ₂ = {lambda2:g}")
ax.set(xlabel="t", ylabel="min ζ", title="damage against the source's growth λ₂")
ax.legend()
fig.tight_layout()
fig.savefig(OUT / "parameter_study.png", dpi=100)

# %% [markdown]
# A change that a scene file would refuse is refused here the same way:

# %%
from solver.errors import ConfigError  # noqa: E402

try:
    base.replace({"damage": {"zeta_star": 1.5}})
except ConfigError as exc:
    print(exc)
