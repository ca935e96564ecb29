"""[mesh]: the built-in rectangle (corners, nx, ny, diagonal) or a gmsh ``.msh`` file."""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass
from pathlib import Path

from ..errors import ConfigError
from .fields import Ctx, check_keys, integer, names, need, string, vector

DIAGONALS = ("right", "left", "right/left", "left/right", "crossed")
MAX_CELLS = 20_000_000  # refuse absurd meshes before allocating anything


@dataclass(frozen=True)
class MeshConfig:
    """Built-in rectangle (corners, nx, ny, diagonal) or a gmsh ``.msh`` file."""

    kind: str = "rectangle"
    corners: tuple[tuple[float, float], tuple[float, float]] = ((0.0, 0.0), (1.0, 1.0))
    nx: int = 16
    ny: int = 16
    diagonal: str = "right"
    file: str = ""


def parse(ctx: Ctx, t: dict, scene: dict) -> MeshConfig:
    t = check_keys(ctx, "mesh", t, names(MeshConfig))
    d = MeshConfig()
    kind = string(ctx, "mesh.kind", t.get("kind", d.kind), ("rectangle", "gmsh"))
    corners = d.corners
    if "corners" in t:
        c = t["corners"]
        if not isinstance(c, list) or len(c) != 2:
            raise ctx.fail("mesh.corners", c, "must be [[x0, y0], [x1, y1]]")
        p0 = vector(ctx, "mesh.corners[0]", c[0], 2)
        p1 = vector(ctx, "mesh.corners[1]", c[1], 2)
        if not (p1[0] > p0[0] and p1[1] > p0[1]):
            raise ctx.fail("mesh.corners", c, "need x1 > x0 and y1 > y0")
        corners = (p0, p1)  # type: ignore[assignment]
    nx = integer(ctx, "mesh.nx", t.get("nx", d.nx))
    ny = integer(ctx, "mesh.ny", t.get("ny", d.ny))
    for key, n in (("mesh.nx", nx), ("mesh.ny", ny)):
        need(ctx, key, n, n >= 1, "must be at least 1")
    cells = nx * ny * (4 if t.get("diagonal") == "crossed" else 2)
    if kind == "rectangle" and cells > MAX_CELLS:
        raise ctx.fail("mesh.nx*mesh.ny", f"{nx}*{ny}", f"gives {cells} cells; at most {MAX_CELLS} are allowed")
    diagonal = string(ctx, "mesh.diagonal", t.get("diagonal", d.diagonal), DIAGONALS)
    file = ""
    if kind == "gmsh":
        if "file" not in t:
            raise ctx.fail("mesh.file", "<missing>", "a gmsh scene needs mesh.file")
        file = string(ctx, "mesh.file", t["file"])
        path = Path(file) if Path(file).is_absolute() else scene["base"] / file
        if not path.is_file():
            raise ctx.fail("mesh.file", file, f"no such file ({path})")
        with open(path, "rb") as fh:
            head = fh.read(11)
        if head != b"$MeshFormat":
            raise ctx.fail("mesh.file", file, "is not a gmsh .msh file")
        file = str(path)
    elif "file" in t:
        raise ctx.fail("mesh.file", t["file"], "only allowed with mesh.kind = 'gmsh'")
    return MeshConfig(kind, corners, nx, ny, diagonal, file)


def to_toml(m: MeshConfig) -> dict:
    if m.kind == "gmsh":
        return {"kind": "gmsh", "file": m.file}
    out = dataclasses.asdict(m)
    out.pop("file")
    return out


def gmsh_dim(path: str) -> int:
    """Geometric dimension of a .msh file: 3 if any node has z != 0."""
    import gmsh  # local import: only gmsh scenes pay for it

    gmsh.initialize()  # gmsh 4.8 (Debian bookworm) has no isInitialized(): own the session here
    try:
        gmsh.option.setNumber("General.Terminal", 0)
        gmsh.model.add("dimension-probe")
        gmsh.merge(path)
        _, coords, _ = gmsh.model.mesh.getNodes()
        dim = 3 if len(coords) and max(abs(coords[2::3])) > 0 else 2
        gmsh.model.remove()
    except Exception as exc:  # gmsh raises plain Exception on unreadable files
        raise ConfigError(f"mesh.file = {path!r}: gmsh cannot read it ({exc})") from None
    finally:
        gmsh.finalize()
    return dim
