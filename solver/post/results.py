"""Reading what a run wrote (never the live solver objects): the XDMF series and the CSV time series."""

from __future__ import annotations

import csv
from pathlib import Path

import numpy as np


def read_results(directory: str | Path) -> dict:
    """Read a results directory through ``solution.xdmf``: node coordinates (``geometry``), cells
    (``topology``), the written ``times``, and ``fields`` {field: {t: values}} (P1 fields per node,
    DG0 fields per cell; tensors as XX, YY, ZZ, XY, YZ, XZ). Rows are in the mesh's input order,
    the same whatever the number of ranks that wrote them (solver/io/xdmf.py)."""
    from solver.io.xdmf import read_series

    res = read_series(Path(directory) / "solution.xdmf")
    out = {"geometry": res["points"], "topology": res["cells"], "times": res["times"], "fields": {}}
    for name, values in res["fields"].items():
        out["fields"][name] = {t: v for t, v in zip(res["times"], values) if v is not None}
    return out


def read_csv(path: str | Path) -> list[dict[str, float]]:
    """Read a timeseries.csv back as a list of rows of floats."""
    with open(path, newline="") as fh:
        return [{k: float(v) for k, v in row.items()} for row in csv.DictReader(fh)]


def read_profile(path: str | Path) -> dict[tuple[int, str], dict[str, np.ndarray]]:
    """Read a contact.csv back: {(step, part): {column: values along the part}} (solver/io/contact_profile.py)."""
    out: dict[tuple[int, str], dict[str, list[float]]] = {}
    with open(path, newline="") as fh:
        for row in csv.DictReader(fh):
            cols = out.setdefault((int(row["step"]), row["part"]), {})
            for k, v in row.items():
                if k not in ("step", "part"):
                    cols.setdefault(k, []).append(float(v))
    return {key: {k: np.asarray(v) for k, v in cols.items()} for key, cols in out.items()}
