"""[boundary.NAME]: named boundary parts and their roles (clamped, traction, contact)."""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

from .fields import Ctx, check_keys, need, number, string, vector
from .mesh import MeshConfig

SIDES = ("left", "right", "bottom", "top")
ROLES = ("clamped", "traction", "contact")
# The paper's Example 1 boundary (docs/model.md §5), used when a scene gives none.
PAPER_BOUNDARIES: dict[str, dict[str, Any]] = {
    "left": {"role": "clamped"},
    "right": {"role": "traction", "traction": [-10.0, -10.0]},
    "bottom": {"role": "contact", "gap": 0.0, "mu": 1e-10},
}
_PER_ROLE = {"clamped": (), "traction": ("traction",), "contact": ("gap", "mu")}


def table_at(rows: tuple[tuple[float, ...], ...], t: float) -> tuple[float, ...]:
    """Value at time ``t`` of a table of rows ``[t, v_1, ...]``, linear in between, left-continuous at jumps."""
    if len(rows) == 1:
        return rows[0][1:]
    times = [r[0] for r in rows]
    if t <= times[0]:
        return rows[0][1:]
    if t >= times[-1]:
        # the first row with the last time: left limit at a final jump
        return rows[times.index(times[-1])][1:]
    i = next(j for j, tj in enumerate(times) if tj >= t)
    if times[i] == t:
        return rows[i][1:]
    t0, t1 = times[i - 1], times[i]
    a = (t - t0) / (t1 - t0)
    return tuple((1 - a) * v0 + a * v1 for v0, v1 in zip(rows[i - 1][1:], rows[i][1:]))


@dataclass(frozen=True)
class BoundaryConfig:
    """One named boundary part and its role.

    On a rectangle, ``side`` (default: the part's name) picks the side and
    ``interval`` an optional sub-interval along it; on a gmsh mesh the name is
    a physical group. ``traction`` is a constant vector, or a table of rows
    ``[t, f_x, f_y(, f_z)]`` interpolated linearly in time (a repeated time is a
    jump; at the jump time the earlier row wins).
    """

    name: str
    role: str
    side: str = ""
    interval: tuple[float, float] | None = None
    traction: tuple[tuple[float, ...], ...] = ()
    gap: float = 0.0
    mu: float = 1e-10

    def traction_at(self, t: float) -> tuple[float, ...]:
        """Traction vector at time ``t`` (left-continuous at jumps)."""
        return table_at(self.traction, t)


def time_table(ctx: Ctx, key: str, v: Any, dim: int) -> tuple[tuple[float, ...], ...]:
    """A constant vector of ``dim`` numbers, or sorted rows ``[t, v_1..v_dim]`` (a time at most twice: a jump)."""
    if not isinstance(v, list) or not v:
        raise ctx.fail(key, v, f"must be a vector of {dim} numbers or a table of rows [t, f_1..f_{dim}]")
    if not isinstance(v[0], list):
        return ((0.0, *vector(ctx, key, v, dim)),)
    rows = tuple(vector(ctx, f"{key}[{i}]", r, dim + 1) for i, r in enumerate(v))
    times = [r[0] for r in rows]
    if any(b < a for a, b in zip(times, times[1:])):
        raise ctx.fail(key, times, "table times must be sorted (a repeated time makes a jump)")
    if any(a == b == c for a, b, c in zip(times, times[1:], times[2:])):
        raise ctx.fail(key, times, "a time may appear at most twice (one jump)")
    return rows


def parse(ctx: Ctx, t: Any, scene: dict) -> tuple[BoundaryConfig, ...]:
    mesh: MeshConfig = scene["mesh"]
    if t is None:
        if mesh.kind != "rectangle":
            raise ctx.fail("boundary", "<missing>", "a gmsh scene must name its boundary parts")
        t = PAPER_BOUNDARIES
    if not isinstance(t, dict) or not t:
        raise ctx.fail("boundary", t, "must hold at least one [boundary.NAME] table")
    out = [_part(ctx, name, b, mesh, scene["dim"]) for name, b in t.items()]
    if not any(b.role == "clamped" for b in out):
        raise ctx.fail("boundary", {b.name: 0 for b in out}, "needs a part with role = 'clamped' (else the body can float)")
    if mesh.kind == "rectangle":
        _check_overlaps(ctx, out, mesh)
    return tuple(out)


def _part(ctx: Ctx, name: str, b: Any, mesh: MeshConfig, dim: int) -> BoundaryConfig:
    sec = f"boundary.{name}"
    b = check_keys(ctx, sec, b, ("role", "side", "interval", "traction", "gap", "mu"))
    if "role" not in b:
        raise ctx.fail(f"{sec}.role", "<missing>", "allowed: " + ", ".join(ROLES))
    role = string(ctx, f"{sec}.role", b["role"], ROLES)
    for key in ("traction", "gap", "mu"):
        if key in b and key not in _PER_ROLE[role]:
            raise ctx.fail(f"{sec}.{key}", b[key], f"not used by role '{role}'")
    side, interval = "", None
    if mesh.kind == "rectangle":
        side = string(ctx, f"{sec}.side", b.get("side", name), SIDES)
        if "interval" in b:
            iv = vector(ctx, f"{sec}.interval", b["interval"], 2)
            (x0, y0), (x1, y1) = mesh.corners
            lo, hi = (x0, x1) if side in ("bottom", "top") else (y0, y1)
            if not (lo <= iv[0] < iv[1] <= hi):
                raise ctx.fail(f"{sec}.interval", list(iv), f"must satisfy {lo} <= a < b <= {hi}")
            interval = (iv[0], iv[1])
    else:
        for key in ("side", "interval"):
            if key in b:
                raise ctx.fail(f"{sec}.{key}", b[key], "only for built-in rectangles; gmsh parts are physical groups")
    traction: tuple[tuple[float, ...], ...] = ()
    if role == "traction":
        if "traction" not in b:
            raise ctx.fail(f"{sec}.traction", "<missing>", "a traction part needs a traction")
        traction = time_table(ctx, f"{sec}.traction", b["traction"], dim)
    gap = number(ctx, f"{sec}.gap", b.get("gap", 0.0))
    mu = number(ctx, f"{sec}.mu", b.get("mu", 1e-10))
    need(ctx, f"{sec}.mu", mu, mu > 0, "must be > 0 (deformability of the foundation)")
    return BoundaryConfig(name, role, side, interval, traction, gap, mu)


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


def to_toml(parts: tuple[BoundaryConfig, ...]) -> dict:
    out: dict[str, Any] = {}
    for b in parts:
        entry: dict[str, Any] = {"role": b.role}
        if b.side:
            entry["side"] = b.side
        if b.interval is not None:
            entry["interval"] = list(b.interval)
        if b.role == "traction":
            entry["traction"] = [list(r) for r in b.traction]
        if b.role == "contact":
            entry["gap"], entry["mu"] = b.gap, b.mu
        out[b.name] = entry
    return out
