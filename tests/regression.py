"""The Example 1 regression values: which run, which quantities, where they are kept.

``scripts/regenerate_reference.py`` rewrites ``data/example1_reference.json`` from this
code; the test compares a fresh run with it. The values are produced by this code
(serial, n = 8, k = 0.05) and reproduced with 2 and 3 ranks to ~1e-14: not published
values, they pin the scheme so that an unintended change shows.
"""

from __future__ import annotations

import json
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
PATH = Path(__file__).with_name("data") / "example1_reference.json"
SCENE = ROOT / "configs" / "example1.toml"
OVERRIDES = ["mesh.nx=8", "mesh.ny=8", "time.k=0.05"]


def quantities(model, rows: list[dict]) -> dict:
    """The regression quantities of a finished run (the same on every rank)."""
    from conftest import point_value

    last = rows[-1]
    return {
        "u11": [float(v) for v in point_value(model.u, [1.0, 1.0])],
        "zeta_min": last["zeta_min"], "zeta_max": last["zeta_max"],
        "force0": rows[0]["contact_force"], "forceT": last["contact_force"],
        "strain_normT": last["strain_norm"], "zeta_normT": last["zeta_norm"],
    }


def load() -> dict:
    return json.loads(PATH.read_text())
