"""[boundary.NAME]: named boundary parts and their roles (clamped, displacement, traction, contact)."""

from __future__ import annotations

from bisect import bisect_left
from dataclasses import dataclass, replace
from pathlib import Path
from typing import Any

import numpy as np

from solver.laws.contact import CONTACT_LAWS, ContactLaw

from .contact import AXES, CONTACT_KEYS, INTERPOLATIONS, LAWS, OBSTACLES, contact_values
from .fields import Ctx, check_keys, number, string, vector
from .mesh import MeshConfig
from .tables import DataTable, as_array, given_as_file, inline, read_csv, row_error, rows_given

__all__ = ["AXES", "BOX_FACES", "FACE_AXIS", "FREE", "INTERPOLATIONS", "LAWS", "OBSTACLES", "PAPER_BOUNDARIES", "ROLES",
           "SIDES", "BoundaryConfig", "Table", "face_bounds", "parse", "table_at", "time_table", "to_toml"]

SIDES = ("left", "right", "bottom", "top")
BOX_FACES = ("left", "right", "front", "back", "bottom", "top")
# a box face: (normal axis, which corner), its two tangential axes in order
FACE_AXIS = {"left": (0, 0), "right": (0, 1), "front": (1, 0), "back": (1, 1), "bottom": (2, 0), "top": (2, 1)}
ROLES = ("clamped", "displacement", "traction", "contact")
FREE = "free"
# The paper's Example 1 boundary (docs/model.md §5), used when a scene gives none.
PAPER_BOUNDARIES: dict[str, dict[str, Any]] = {
    "left": {"role": "clamped"},
    "right": {"role": "traction", "traction": [-10.0, -10.0]},
    "bottom": {"role": "contact", "gap": 0.0, "mu": 1e-10},
}
_PER_ROLE = {"clamped": (), "displacement": ("displacement",), "traction": ("traction",), "contact": CONTACT_KEYS}
_KEYS = ("role", "side", "interval", "traction", "displacement", *CONTACT_KEYS)

Table = tuple[tuple[float, ...], ...]


def table_at(rows: tuple[tuple[float, ...], ...], t: float) -> tuple[float, ...]:
    """Value at time ``t`` of a table of rows ``[t, v_1, ...]``, linear in between, left-continuous at jumps."""
    if len(rows) == 1:
        return rows[0][1:]
    if t <= rows[0][0]:
        return rows[0][1:]
    if t >= rows[-1][0]:
        # the first row with the last time: left limit at a final jump
        return rows[bisect_left(rows, rows[-1][0], key=_time)][1:]
    i = bisect_left(rows, t, key=_time)  # the first row at or after t (O(log n): tables may come from files)
    if rows[i][0] == t:
        return rows[i][1:]
    t0, t1 = rows[i - 1][0], rows[i][0]
    a = (t - t0) / (t1 - t0)
    return tuple((1 - a) * v0 + a * v1 for v0, v1 in zip(rows[i - 1][1:], rows[i][1:]))


def _time(row: tuple[float, ...]) -> float:
    return row[0]


@dataclass(frozen=True)
class BoundaryConfig:
    """One named boundary part and its role.

    On a rectangle, ``side`` (default: the part's name) picks the side and
    ``interval`` an optional sub-interval along it; on a box, ``side`` picks a face
    (left/right: x, front/back: y, bottom/top: z) and ``patch`` an optional
    sub-rectangle [[a0, a1], [b0, b1]] in its two tangential coordinates (in x, y, z
    order; TOML key ``interval``); on a gmsh mesh the name is a physical group. ``traction`` is a constant vector, or a table of rows
    ``[t, f_x, f_y(, f_z)]`` interpolated linearly in time (a repeated time is a
    jump; at the jump time the earlier row wins).

    ``displacement`` (role ``displacement``): one entry per component, each a table of
    rows (t, value) linear in t, or None for a free component (``clamped`` is all zeros).

    Contact: the gap is ``gap`` or, when ``gap_table`` holds rows (s, g), piecewise linear
    in the coordinate ``gap_coordinate`` (held constant beyond the table; ``gap_interpolation``
    = "cubic": a C² spline through the rows), or an analytic rigid ``obstacle`` (a plane, a
    circle or a sphere; solver/physics/gap.py). The compliance law p(r) of
    -sigma_nu = p(u_nu - g) is ``law`` with its parameters (``mu``, ``coefficient``, ...):
    :attr:`contact_law` is the law object (solver/laws/contact.py) those fields make.
    """

    name: str
    role: str
    side: str = ""
    interval: tuple[float, float] | None = None
    traction: Table = ()
    gap: float = 0.0
    mu: float = 1e-10
    gap_table: tuple[tuple[float, float], ...] = ()
    gap_coordinate: str = ""
    gap_interpolation: str = "linear"
    obstacle: tuple[tuple[str, Any], ...] = ()  # (key, value) pairs: shape, point/normal or centre/radius
    law: str = "linear"
    coefficient: float = 0.0
    exponent: float = 1.0
    depth: float = 0.0
    mu_stiff: float = 1e-10
    displacement: tuple[Table | None, ...] = ()
    patch: tuple[tuple[float, float], tuple[float, float]] | None = None

    @property
    def contact_law(self) -> ContactLaw:
        """The part's compliance law p (role contact), from ``law`` and its parameters."""
        law = CONTACT_LAWS[self.law]
        return law(**{key: getattr(self, key) for key in law.keys()})

    def traction_at(self, t: float) -> tuple[float, ...]:
        """Traction vector at time ``t`` (left-continuous at jumps)."""
        return table_at(self.traction, t)

    @property
    def dirichlet(self) -> bool:
        """Whether the part prescribes displacements (clamped or displacement)."""
        return self.role in ("clamped", "displacement")

    def fixed(self, dim: int) -> tuple[bool, ...]:
        """Which components the part prescribes."""
        if self.role == "clamped":
            return (True,) * dim
        if self.role == "displacement":
            return tuple(c is not None for c in self.displacement)
        return (False,) * dim

    def displacement_at(self, t: float, dim: int) -> tuple[float | None, ...]:
        """Prescribed value of each component at time ``t`` (None: free)."""
        if self.role == "clamped":
            return (0.0,) * dim
        return tuple(None if c is None else table_at(c, t)[0] for c in self.displacement)

    @property
    def inhomogeneous(self) -> bool:
        """Whether a prescribed value differs from zero at some time (K's lifting then enters b)."""
        return self.role == "displacement" and any(
            c is not None and any(v != 0.0 for r in c for v in r[1:]) for c in self.displacement)


def time_table(ctx: Ctx, key: str, v: Any, dim: int, base: Path | None = None,
               labels: tuple[str, ...] | None = None) -> tuple[tuple[float, ...], ...]:
    """A constant vector of ``dim`` numbers, or sorted rows ``[t, v_1..v_dim]`` (a time at most twice: a jump),
    inline or from a CSV file ``{file, columns}`` (found relative to ``base``; ``labels``: its columns' names)."""
    labels = labels or ("t", *(f"f_{a}" for a in AXES[:dim]))
    if given_as_file(v):
        rows = read_csv(ctx, key, v, base or Path.cwd(), labels)
    else:
        if not isinstance(v, (list, DataTable)) or not v:
            raise ctx.fail(key, v, f"must be a vector of {dim} numbers, a table of rows [t, f_1..f_{dim}] or "
                           "{file = 'table.csv', columns = [...]}")
        if not rows_given(v) and not isinstance(v[0], list):
            return ((0.0, *vector(ctx, key, v, dim)),)
        rows = inline(ctx, key, v, dim + 1, f"[{', '.join(labels)}]")
    times = as_array(rows)[:, 0]
    back = np.flatnonzero(times[1:] < times[:-1])
    if len(back):
        i = int(back[0]) + 1
        raise row_error(ctx, key, rows, i, [times[i - 1], times[i]],
                        "table times must be sorted (a repeated time makes a jump)")
    thrice = np.flatnonzero((times[2:] == times[1:-1]) & (times[1:-1] == times[:-2]))
    if len(thrice):
        i = int(thrice[0]) + 2
        raise row_error(ctx, key, rows, i, float(times[i]), "a time may appear at most twice (one jump)")
    return rows


def parse(ctx: Ctx, t: Any, scene: dict) -> tuple[BoundaryConfig, ...]:
    mesh: MeshConfig = scene["mesh"]
    dim = scene["dim"]
    if t is None:
        if mesh.kind != "rectangle":
            raise ctx.fail("boundary", "<missing>", f"a {mesh.kind} scene must name its boundary parts")
        t = PAPER_BOUNDARIES
    if not isinstance(t, dict) or not t:
        raise ctx.fail("boundary", t, "must hold at least one [boundary.NAME] table")
    out = [_part(ctx, name, b, mesh, dim, scene["base"]) for name, b in t.items()]
    _check_rigid_motions(ctx, out, dim)
    if mesh.kind == "rectangle":
        _check_overlaps(ctx, out, mesh)
    if mesh.kind == "box":
        _check_box_overlaps(ctx, out, mesh)
    return tuple(out)


def _check_rigid_motions(ctx: Ctx, parts: list[BoundaryConfig], dim: int) -> None:
    """Every direction must be prescribed by some Dirichlet part (else the body translates freely).

    Rotations are checked on the mesh (:func:`solver.physics.operators.check_rigid_motions`).
    """
    for i, axis in enumerate(AXES[:dim]):
        if not any(b.fixed(dim)[i] for b in parts):
            raise ctx.fail("boundary", {b.name: 0 for b in parts},
                           f"no part fixes u_{axis}: needs a part with role = 'clamped', or role = 'displacement' "
                           f"with u_{axis} not 'free' (else the body can float)")


def _part(ctx: Ctx, name: str, b: Any, mesh: MeshConfig, dim: int, base: Path) -> BoundaryConfig:
    sec = f"boundary.{name}"
    b = check_keys(ctx, sec, b, _KEYS)
    if "role" not in b:
        raise ctx.fail(f"{sec}.role", "<missing>", "allowed: " + ", ".join(ROLES))
    role = string(ctx, f"{sec}.role", b["role"], ROLES)
    for key in ("traction", "displacement", *CONTACT_KEYS):
        if key in b and key not in _PER_ROLE[role]:
            raise ctx.fail(f"{sec}.{key}", b[key], f"not used by role '{role}'")
    side, interval, patch = "", None, None
    if mesh.kind == "rectangle":
        side = string(ctx, f"{sec}.side", b.get("side", name), SIDES)
        if "interval" in b:
            iv = vector(ctx, f"{sec}.interval", b["interval"], 2)
            (x0, y0), (x1, y1) = mesh.corners
            lo, hi = (x0, x1) if side in ("bottom", "top") else (y0, y1)
            if not (lo <= iv[0] < iv[1] <= hi):
                raise ctx.fail(f"{sec}.interval", list(iv), f"must satisfy {lo} <= a < b <= {hi}")
            interval = (iv[0], iv[1])
    elif mesh.kind == "box":
        side = string(ctx, f"{sec}.side", b.get("side", name), BOX_FACES)
        if "interval" in b:
            patch = _patch(ctx, f"{sec}.interval", b["interval"], side, mesh)
    else:
        for key in ("side", "interval"):
            if key in b:
                raise ctx.fail(f"{sec}.{key}", b[key], "only for built-in rectangles and boxes; gmsh parts are physical groups")
    part = BoundaryConfig(name, role, side, interval, patch=patch)
    if role == "traction":
        if "traction" not in b:
            raise ctx.fail(f"{sec}.traction", "<missing>", "a traction part needs a traction")
        return replace(part, traction=time_table(ctx, f"{sec}.traction", b["traction"], dim, base))
    if role == "displacement":
        return replace(part, displacement=_displacement(ctx, f"{sec}.displacement", b, dim, base))
    if role == "contact":
        return replace(part, **contact_values(ctx, sec, b, side, mesh, dim, base))
    return part


def face_bounds(side: str, corners) -> tuple[tuple[float, float], tuple[float, float]]:
    """The full extent of a box face in its two tangential coordinates (x, y, z order)."""
    axis = FACE_AXIS[side][0]
    return tuple((corners[0][a], corners[1][a]) for a in range(3) if a != axis)  # type: ignore[return-value]


def _patch(ctx: Ctx, key: str, v: Any, side: str, mesh: MeshConfig) -> tuple[tuple[float, float], tuple[float, float]]:
    """A sub-rectangle [[a0, a1], [b0, b1]] of a box face, inside the face."""
    tang = "".join(a for i, a in enumerate("xyz") if i != FACE_AXIS[side][0])
    if not isinstance(v, list) or len(v) != 2:
        raise ctx.fail(key, v, f"must be [[{tang[0]}0, {tang[0]}1], [{tang[1]}0, {tang[1]}1]] on face '{side}'")
    out = []
    for i, ((lo, hi), r) in enumerate(zip(face_bounds(side, mesh.corners), v)):
        iv = vector(ctx, f"{key}[{i}]", r, 2)
        if not (lo <= iv[0] < iv[1] <= hi):
            raise ctx.fail(f"{key}[{i}]", list(iv), f"must satisfy {lo} <= a < b <= {hi} ({tang[i]} on face '{side}')")
        out.append((iv[0], iv[1]))
    return (out[0], out[1])


def _displacement(ctx: Ctx, key: str, b: dict, dim: int, base: Path) -> tuple[Table | None, ...]:
    """Per component: a number, a table of rows [t, value] (inline or {file, columns}), or "free"; at least one
    component fixed."""
    if "displacement" not in b:
        raise ctx.fail(key, "<missing>", f"a displacement part needs displacement = [{', '.join(['u'] * dim)}]")
    v = b["displacement"]
    if not isinstance(v, list) or len(v) != dim:
        raise ctx.fail(key, v, f"must list {dim} components, each a number, a table of rows [t, value] or 'free'")
    comps: list[Table | None] = []
    for i, c in enumerate(v):
        ck = f"{key}[{i}]"
        if c == FREE:
            comps.append(None)
        elif given_as_file(c):
            comps.append(time_table(ctx, ck, c, 1, base, ("t", f"u_{AXES[i]}")))
        elif isinstance(c, (list, DataTable)):
            if not rows_given(c):
                raise ctx.fail(ck, c, "a table must be rows [t, value] (or give a number, or 'free')")
            comps.append(time_table(ctx, ck, c, 1, base, ("t", f"u_{AXES[i]}")))
        elif isinstance(c, str):
            raise ctx.fail(ck, c, "a number, a table of rows [t, value], or 'free'")
        else:
            comps.append(((0.0, number(ctx, ck, c)),))
    if all(c is None for c in comps):
        raise ctx.fail(key, v, "every component is 'free': give at least one value (or drop the part)")
    return tuple(comps)


def _check_overlaps(ctx: Ctx, parts: list[BoundaryConfig], mesh: MeshConfig) -> None:
    (x0, y0), (x1, y1) = mesh.corners
    full = {"left": (y0, y1), "right": (y0, y1), "bottom": (x0, x1), "top": (x0, x1)}
    for i, a in enumerate(parts):
        for b in parts[i + 1 :]:
            if a.side != b.side:
                continue
            ia, ib = a.interval or full[a.side], b.interval or full[b.side]
            if min(ia[1], ib[1]) > max(ia[0], ib[0]):
                raise ctx.fail(
                    f"boundary.{b.name}", f"{b.side} {list(ib)}",
                    f"overlaps boundary.{a.name} ({a.side} {list(ia)}); a part of the boundary has one role",
                )


def _check_box_overlaps(ctx: Ctx, parts: list[BoundaryConfig], mesh: MeshConfig) -> None:
    """Two parts on one box face must not share area."""
    for i, a in enumerate(parts):
        for b in parts[i + 1 :]:
            if a.side != b.side:
                continue
            pa = a.patch or face_bounds(a.side, mesh.corners)
            pb = b.patch or face_bounds(b.side, mesh.corners)
            if all(min(ia[1], ib[1]) > max(ia[0], ib[0]) for ia, ib in zip(pa, pb)):
                raise ctx.fail(
                    f"boundary.{b.name}", f"{b.side} {[list(r) for r in pb]}",
                    f"overlaps boundary.{a.name} ({a.side} {[list(r) for r in pa]}); a part of the boundary has one role",
                )


def to_toml(parts: tuple[BoundaryConfig, ...]) -> dict:
    out: dict[str, Any] = {}
    for b in parts:
        entry: dict[str, Any] = {"role": b.role}
        if b.side:
            entry["side"] = b.side
        if b.interval is not None:
            entry["interval"] = list(b.interval)
        if b.patch is not None:
            entry["interval"] = [list(r) for r in b.patch]
        if b.role == "traction":
            entry["traction"] = b.traction  # rows (a file's stay a DataTable: scene.dumps_referring refers to them)
        if b.role == "displacement":
            entry["displacement"] = [_component_toml(c) for c in b.displacement]
        if b.role == "contact":
            if b.obstacle:
                entry["obstacle"] = {k: (list(v) if isinstance(v, tuple) else v) for k, v in b.obstacle}
            elif b.gap_table:
                entry["gap"], entry["gap_coordinate"] = b.gap_table, b.gap_coordinate
                if b.gap_interpolation != "linear":
                    entry["gap_interpolation"] = b.gap_interpolation
            else:
                entry["gap"] = b.gap
            entry["law"] = b.law
            entry.update(b.contact_law.parameters())
        out[b.name] = entry
    return out


def _component_toml(c: Table | None) -> Any:
    if c is None:
        return FREE
    if len(c) == 1 and c[0][0] == 0.0 and not isinstance(c, DataTable):
        return c[0][1]
    return c
