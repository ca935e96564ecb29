"""Whether two results directories hold the same run: the restart checks' comparison (tests and the Slurm check).

Rows of ``timeseries.csv`` column by column, and the node fields of ``solution.xdmf`` at every written time, matched
point by point through the sorted node coordinates (two runs on different numbers of ranks number their nodes
alike, but the comparison does not rely on it). Values agree when |a - b| <= max(atol, rtol |b|), elementwise.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from solver.io.layout import ResultsDir
from solver.post.results import read_csv, read_results

# columns that differ between equal runs: clocks, and a restart factorizing its matrix again
UNCOMPARED = ("wall_time", "factorizations")


@dataclass
class Comparison:
    """``levels``: CSV rows compared; ``written``: field times compared; ``worst``: the largest |a - b| / max(|b|, 1)
    over everything compared; ``differences``: what disagrees (empty: the same run)."""

    levels: int = 0
    written: int = 0
    worst: float = 0.0
    differences: list[str] = field(default_factory=list)

    @property
    def same(self) -> bool:
        return not self.differences


def compare_runs(a: str | Path, b: str | Path, rtol: float = 1e-12, atol: float = 1e-12) -> Comparison:
    """Compare the results directory ``a`` with the reference ``b`` (cell fields are left out: they are computed
    from the node fields compared here)."""
    out = Comparison()
    ra, rb = read_csv(ResultsDir(Path(a)).timeseries), read_csv(ResultsDir(Path(b)).timeseries)
    if len(ra) != len(rb):
        out.differences.append(f"timeseries.csv: {len(ra)} rows against {len(rb)}")
    for x, y in zip(ra, rb):
        for c, yc in y.items():
            if c.startswith("time_") or c in UNCOMPARED:
                continue
            _check(out, f"timeseries.csv step {int(y['step'])} {c}", np.array(x.get(c, np.nan)), np.array(yc),
                   rtol, atol)
    out.levels = min(len(ra), len(rb))
    ga, gb = read_results(a), read_results(b)
    if ga["times"] != gb["times"]:
        out.differences.append(f"written times differ: {ga['times']} against {gb['times']}")
        return out
    xa, xb = np.round(ga["geometry"], 12), np.round(gb["geometry"], 12)
    oa, ob = np.lexsort(xa.T[::-1]), np.lexsort(xb.T[::-1])
    if xa.shape != xb.shape or not np.array_equal(xa[oa], xb[ob]):
        out.differences.append("the meshes' nodes differ")
        return out
    for name, values in gb["fields"].items():
        for t, v in values.items():
            if len(v) != len(xb):
                continue  # a cell field
            got = ga["fields"].get(name, {}).get(t)
            if got is None:
                out.differences.append(f"{name} at t = {t:g}: missing")
                continue
            _check(out, f"{name} at t = {t:g}", got[oa], v[ob], rtol, atol)
    out.written = len(gb["times"])
    return out


def _check(out: Comparison, where: str, a: np.ndarray, b: np.ndarray, rtol: float, atol: float) -> None:
    diff = np.abs(a - b)
    out.worst = max(out.worst, float(np.max(diff / np.maximum(np.abs(b), 1.0), initial=0.0)))
    if not np.all(diff <= np.maximum(atol, rtol * np.abs(b))):
        out.differences.append(f"{where}: largest difference {float(np.nanmax(diff, initial=np.inf)):.3g}")
