# ---
# jupyter:
#   jupytext:
#     formats: py:percent
#     text_representation:
#       extension: .py
#       format_name: percent
# ---

# %% [markdown]
# # Reading results back
#
# A results directory, written by `python -m solver run` or `api.run(cfg, directory)`, is read back with
# `api.read` (the time series and the last level's fields) or, for every written level, with
# `solver.post.results.read_results`. Nothing here needs the solver's live objects: this is post-processing of
# files, as on another machine.

# %%
import os
from pathlib import Path

import matplotlib
import numpy as np

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402

from solver import api  # noqa: E402
from solver.post.results import read_results  # noqa: E402

ROOT = Path(__file__).resolve().parents[1] if "__file__" in globals() else Path.cwd()
OUT = Path(os.environ.get("DEMO_OUTPUT", ROOT / "results" / "demos"))
RUN = OUT / "example1_every10"

# %% [markdown]
# A run to read: Example 1, every 10th level written.

# %%
cfg = api.load(ROOT / "configs" / "example1.toml").replace({"output": {"every": 10}})
api.run(cfg, RUN, overwrite=True)

# %% [markdown]
# ## The time series and the last level

# %%
res = api.read(RUN)
print("levels in the CSV:", len(res.series["t"]), "| fields at the end:", sorted(res.fields))
print("table of (t, contact force) every 25 levels:\n", res.table("t", "contact_force")[::25])

# %% [markdown]
# ## Every written level
#
# `read_results` gives the node coordinates, the cells, the written times and each field at each time (node
# fields per node, cell fields per cell, in the mesh's input order whatever the number of ranks that wrote it).
# Here: the damage along the contact side y = 0 at each written time.

# %%
full = read_results(RUN)
x, y = full["geometry"][:, 0], full["geometry"][:, 1]
bottom = np.flatnonzero(np.abs(y) < 1e-12)
bottom = bottom[np.argsort(x[bottom])]
fig, ax = plt.subplots(figsize=(5, 3.4))
for t in full["times"][::2]:
    ax.plot(x[bottom], full["fields"]["damage"][t].ravel()[bottom], label=f"t = {t:g}")
ax.set(xlabel="x on the contact side", ylabel="ζ", title="damage along the foundation")
ax.legend(fontsize=8)
fig.tight_layout()
fig.savefig(OUT / "read_results.png", dpi=100)
print("written times:", full["times"])
