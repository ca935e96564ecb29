"""The keys of a contact part ([boundary.NAME] with role = "contact"): its gap (a number, a table or an analytic
obstacle) and its compliance law, which the law's class reads and validates (solver/laws/contact.py)."""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np

from solver.laws.contact import CONTACT_LAWS

from .fields import Ctx, check_keys, need, number, string, vector
from .mesh import MeshConfig
from .tables import DataTable, as_array, given_as_file, inline, read_csv, row_error, rows_given

LAWS = tuple(CONTACT_LAWS)  # the contact laws' names
AXES = ("x", "y", "z")
INTERPOLATIONS = ("linear", "cubic")
# analytic rigid obstacles (solver/physics/gap.py) and their keys
OBSTACLES = {"plane": ("point", "normal"), "circle": ("centre", "radius"), "sphere": ("centre", "radius")}
# every law's keys (each law's own: CONTACT_LAWS[name].keys())
_LAW_PARAMETERS = tuple(dict.fromkeys(key for law in CONTACT_LAWS.values() for key in law.keys()))
CONTACT_KEYS = ("gap", "gap_coordinate", "gap_interpolation", "obstacle", "law", *_LAW_PARAMETERS)


def contact_values(ctx: Ctx, sec: str, b: dict, side: str, mesh: MeshConfig, dim: int, base: Path) -> dict[str, Any]:
    """The BoundaryConfig fields of a contact part's table ``b`` (section ``sec``; ``side``: its side or face;
    ``base``: the scene file's folder, where a gap table's file is found)."""
    name = string(ctx, f"{sec}.law", b.get("law", "linear"), LAWS)
    law = CONTACT_LAWS[name]
    for key in _LAW_PARAMETERS:
        if key in b and key not in law.keys():
            raise ctx.fail(f"{sec}.{key}", b[key], f"not used by law '{name}' (it takes {', '.join(law.keys())})")
    values: dict[str, Any] = {"law": name, **law.parse(_LawTable(ctx, sec, b)).parameters()}
    gap = b.get("gap", 0.0)
    if "obstacle" in b:
        if "gap" in b or "gap_coordinate" in b or "gap_interpolation" in b:
            raise ctx.fail(f"{sec}.obstacle", b["obstacle"], "an obstacle replaces gap, gap_coordinate, gap_interpolation")
        values["obstacle"] = _obstacle(ctx, f"{sec}.obstacle", b["obstacle"], dim)
    elif isinstance(gap, (list, DataTable)) or given_as_file(gap):
        values["gap_interpolation"] = string(ctx, f"{sec}.gap_interpolation", b.get("gap_interpolation", "linear"),
                                             INTERPOLATIONS)
        values["gap_table"] = _gap_table(ctx, f"{sec}.gap", gap, base)
        values["gap_coordinate"] = _gap_coordinate(ctx, sec, b, side, mesh, dim)
    else:
        values["gap"] = number(ctx, f"{sec}.gap", gap)
        if "gap_coordinate" in b:
            raise ctx.fail(f"{sec}.gap_coordinate", b["gap_coordinate"], "only with a gap table [[s, g], ...]")
        if "gap_interpolation" in b:
            raise ctx.fail(f"{sec}.gap_interpolation", b["gap_interpolation"], "only with a gap table [[s, g], ...]")
    return values


class _LawTable:
    """A contact part's table as its law reads it (:class:`solver.laws.contact.LawTable`): keys ``{sec}.key``."""

    def __init__(self, ctx: Ctx, sec: str, table: dict) -> None:
        self.ctx, self.sec, self.table = ctx, sec, table

    def given(self, key: str) -> bool:
        return key in self.table

    def number(self, key: str, default: float | None = None) -> float:
        return number(self.ctx, f"{self.sec}.{key}", self.table.get(key, default))

    def fail(self, key: str, value: Any, allowed: str) -> Exception:
        return self.ctx.fail(f"{self.sec}.{key}", value, allowed)


def _obstacle(ctx: Ctx, key: str, v: Any, dim: int) -> tuple[tuple[str, Any], ...]:
    """{shape = "plane", point, normal} or {shape = "circle" (2-D) | "sphere" (3-D), centre, radius}."""
    if not isinstance(v, dict):
        raise ctx.fail(key, v, "must be a table {shape = 'plane' | 'circle' | 'sphere', ...}")
    shape = string(ctx, f"{key}.shape", v.get("shape"), tuple(OBSTACLES))
    need(ctx, f"{key}.shape", shape, shape != ("sphere" if dim == 2 else "circle"),
         "a circle is 2-D, a sphere 3-D")
    check_keys(ctx, key, v, ("shape", *OBSTACLES[shape]))
    out: list[tuple[str, Any]] = [("shape", shape)]
    for name in OBSTACLES[shape]:
        if name not in v:
            raise ctx.fail(f"{key}.{name}", "<missing>", f"a {shape} needs " + ", ".join(OBSTACLES[shape]))
        if name == "radius":
            r = number(ctx, f"{key}.radius", v[name])
            need(ctx, f"{key}.radius", r, r > 0, "must be > 0")
            out.append((name, r))
        else:
            vec = vector(ctx, f"{key}.{name}", v[name], dim)
            if name == "normal":
                need(ctx, f"{key}.normal", list(vec), any(c != 0.0 for c in vec), "must not be zero")
            out.append((name, vec))
    return tuple(out)


def _gap_table(ctx: Ctx, key: str, v: Any, base: Path) -> tuple[tuple[float, float], ...]:
    """Rows [s, g] inline or from a CSV file ({file, columns = [s, g]}), s increasing strictly."""
    if given_as_file(v):
        rows = read_csv(ctx, key, v, base, ("s", "g"))
    else:
        if not rows_given(v):
            raise ctx.fail(key, v, "must be a number, a table of rows [s, g] (piecewise linear in s) or "
                           "{file = 'profile.csv', columns = [s, g]}")
        rows = inline(ctx, key, v, 2, "[s, g]")
    s = as_array(rows)[:, 0]
    down = np.flatnonzero(s[1:] <= s[:-1])
    if len(down):
        i = int(down[0]) + 1
        raise row_error(ctx, key, rows, i, [rows[i - 1][0], rows[i][0]], "the coordinates s must increase strictly")
    return rows  # type: ignore[return-value]


def _gap_coordinate(ctx: Ctx, sec: str, b: dict, side: str, mesh: MeshConfig, dim: int) -> str:
    """x along a horizontal side, y along a vertical one; required on gmsh parts."""
    if "gap_coordinate" in b:
        return string(ctx, f"{sec}.gap_coordinate", b["gap_coordinate"], AXES[:dim])
    if mesh.kind != "rectangle":  # a box face has two tangential coordinates: say which
        raise ctx.fail(f"{sec}.gap_coordinate", "<missing>",
                       f"a gap table on a {mesh.kind} part needs gap_coordinate = " + " | ".join(f"'{a}'" for a in AXES[:dim]))
    return "x" if side in ("bottom", "top") else "y"
