"""Reading what a run wrote (never the live solver objects): the XDMF series and the CSV time series."""

from __future__ import annotations

import csv
from pathlib import Path

import numpy as np

from solver.errors import ResultsError
from solver.io.layout import PROFILE_COLUMNS, ResultsDir
from solver.io.xdmf import read_series


def read_results(directory: str | Path) -> dict:
    """Read a results directory through ``solution.xdmf``: node coordinates (``geometry``), cells
    (``topology``), the written ``times``, and ``fields`` {field: {t: values}} (P1 fields per node,
    DG0 fields per cell; tensors as XX, YY, ZZ, XY, YZ, XZ). Rows are in the mesh's input order,
    the same whatever the number of ranks that wrote them (solver/io/xdmf.py). A damaged directory is a
    :class:`ResultsError` naming the file and what is wrong."""
    path = ResultsDir(Path(directory)).solution
    res = read_series(path)
    out = {"geometry": res["points"], "topology": res["cells"], "times": res["times"], "fields": {}}
    for name, values in res["fields"].items():
        out["fields"][name] = {t: v for t, v in zip(res["times"], values) if v is not None}
    for t, u in out["fields"].get("displacement", {}).items():  # what warps the body: a vector at every node
        if u.ndim != 2 or len(u) != len(res["points"]) or u.shape[1] < res["points"].shape[1]:
            raise ResultsError(path, f"displacement at t = {t:g}: shape {u.shape}, not a vector at each of the "
                                     f"{len(res['points'])} nodes")
    return out


def read_csv(path: str | Path, need: tuple[str, ...] = ()) -> list[dict[str, float]]:
    """Read a timeseries.csv back as a list of rows of floats. A file that cannot be read as such (not text, a
    short or long row, a value that is no number, a column of ``need`` missing) is a :class:`ResultsError` naming
    the file, the line and the column."""
    return [{k: _number(path, n, k, v) for k, v in row.items()} for n, row in _rows(path, need)]


def _rows(path: str | Path, need: tuple[str, ...]) -> list[tuple[int, dict[str, str]]]:
    """(line number, row) of a CSV file with a header line, every row as long as the header."""
    try:
        with open(path, newline="", encoding="utf-8") as fh:
            reader = csv.DictReader(fh)
            rows = [(reader.line_num, row) for row in reader]
            header = reader.fieldnames or []
    except (OSError, UnicodeDecodeError, csv.Error) as exc:
        raise ResultsError(path, f"cannot be read as CSV text ({exc})") from None
    missing = [k for k in need if k not in header]
    if missing:
        has = ", ".join(header[:8]) + (", ..." if len(header) > 8 else "") if header else "no header line"
        raise ResultsError(path, f"no column {', '.join(missing)} (it has {has})")
    for n, row in rows:
        if None in row or None in row.values():
            raise ResultsError(path, f"line {n}: {len(header)} columns in the header, another number in this row")
    return rows


def _number(path: str | Path, line: int, key: str, value: str) -> float:
    try:
        return float(value)
    except ValueError:
        raise ResultsError(path, f"line {line}: {key} = {value[:40]!r} is not a number") from None


# what read_profile needs of contact.csv: every column but the point's coordinates
PROFILE_NEEDED = tuple(c for c in PROFILE_COLUMNS if c not in ("x", "y", "z"))


def read_profile(path: str | Path) -> dict[tuple[int, str], dict[str, np.ndarray]]:
    """Read a contact.csv back: {(step, part): {column: values along the part}} (solver/io/contact_profile.py);
    a damaged file is a :class:`ResultsError` as in :func:`read_csv`."""
    out: dict[tuple[int, str], dict[str, list[float]]] = {}
    for n, row in _rows(path, PROFILE_NEEDED):
        step = _number(path, n, "step", row["step"])
        if not (np.isfinite(step) and step == int(step)):
            raise ResultsError(path, f"line {n}: step = {row['step'][:40]!r} is not a whole number")
        cols = out.setdefault((int(step), row["part"]), {})
        for k, v in row.items():
            if k not in ("step", "part"):
                cols.setdefault(k, []).append(_number(path, n, k, v))
    return {key: {k: np.asarray(v) for k, v in cols.items()} for key, cols in out.items()}


def contact_levels(profile: dict[tuple[int, str], dict[str, np.ndarray]]) -> dict[str, dict[str, np.ndarray]]:
    """:func:`read_profile`'s levels stacked per part: {part: {"step": (levels,), "t": (levels,), column: (levels,
    nodes)}} for the columns s, x, y, z, gap, u_normal, penetration, pressure, a row a written level in step order."""
    out: dict[str, dict[str, np.ndarray]] = {}
    for part in sorted({name for _, name in profile}):
        steps = sorted(step for step, name in profile if name == part)
        levels = [profile[(step, part)] for step in steps]
        cols = {"step": np.array(steps), "t": np.array([lv["t"][0] if len(lv["t"]) else np.nan for lv in levels])}
        for k in levels[0]:
            if k != "t":
                cols[k] = np.array([lv[k] for lv in levels])
        out[part] = cols
    return out


def read_contact(directory: str | Path) -> dict[str, dict[str, np.ndarray]]:
    """A results directory's contact results (``contact.csv``), per contact part as arrays (:func:`contact_levels`):
    ``read_contact("results/example1")["bottom"]["pressure"][-1]`` is the pressure along the part at the last written
    level. {} for a scene without contact (no contact.csv); a damaged file is a :class:`ResultsError`."""
    path = ResultsDir(Path(directory)).contact
    return contact_levels(read_profile(path)) if path.exists() else {}
