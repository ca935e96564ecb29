"""[mesh]: the built-in rectangle (corners, nx, ny, diagonal), box (corners, nx, ny, nz) or a gmsh ``.msh`` file."""

from __future__ import annotations

import dataclasses
import functools
import os
from dataclasses import dataclass
from pathlib import Path

from solver.errors import ConfigError

from .fields import Ctx, check_keys, integer, names, need, string, vector

DIAGONALS = ("right", "left", "right/left", "left/right", "crossed")
BUILT_IN = ("rectangle", "box")
BOX_CORNERS = ((0.0, 0.0, 0.0), (1.0, 1.0, 1.0))
MAX_CELLS = 20_000_000  # refuse absurd meshes before allocating anything


@dataclass(frozen=True)
class MeshConfig:
    """Built-in rectangle (corners, nx, ny, diagonal), box (corners in 3-D, nx, ny, nz; tetrahedra)
    or a gmsh ``.msh`` file. ``corners`` has two points of 2 (rectangle) or 3 (box) coordinates."""

    kind: str = "rectangle"
    corners: tuple[tuple[float, ...], tuple[float, ...]] = ((0.0, 0.0), (1.0, 1.0))
    nx: int = 16
    ny: int = 16
    diagonal: str = "right"
    file: str = ""
    nz: int = 16

    @property
    def dim(self) -> int:
        """Geometric dimension of a built-in mesh (3 for a box, else 2)."""
        return 3 if self.kind == "box" else 2


def parse(ctx: Ctx, t: dict, scene: dict) -> MeshConfig:
    t = check_keys(ctx, "mesh", t, names(MeshConfig))
    d = MeshConfig()
    kind = string(ctx, "mesh.kind", t.get("kind", d.kind), ("rectangle", "box", "gmsh"))
    gdim = 3 if kind == "box" else 2
    corners = BOX_CORNERS if kind == "box" else d.corners
    if "corners" in t:
        c = t["corners"]
        shape = "[[x0, y0, z0], [x1, y1, z1]]" if gdim == 3 else "[[x0, y0], [x1, y1]]"
        if not isinstance(c, list) or len(c) != 2:
            raise ctx.fail("mesh.corners", c, f"must be {shape}")
        p0 = vector(ctx, "mesh.corners[0]", c[0], gdim)
        p1 = vector(ctx, "mesh.corners[1]", c[1], gdim)
        if not all(b > a for a, b in zip(p0, p1)):
            raise ctx.fail("mesh.corners", c, "need " + " and ".join(f"{a}1 > {a}0" for a in "xyz"[:gdim]))
        corners = (p0, p1)  # type: ignore[assignment]
    nx = integer(ctx, "mesh.nx", t.get("nx", d.nx))
    ny = integer(ctx, "mesh.ny", t.get("ny", d.ny))
    nz = integer(ctx, "mesh.nz", t.get("nz", d.nz))
    for key, n in (("mesh.nx", nx), ("mesh.ny", ny), ("mesh.nz", nz)):
        need(ctx, key, n, n >= 1, "must be at least 1")
    if "nz" in t and kind != "box":
        raise ctx.fail("mesh.nz", t["nz"], "only allowed with mesh.kind = 'box'")
    if "diagonal" in t and kind == "box":
        raise ctx.fail("mesh.diagonal", t["diagonal"],
                       "only allowed with mesh.kind = 'rectangle' (a box is cut into 6 tetrahedra per cell)")
    cells = nx * ny * (4 if t.get("diagonal") == "crossed" else 2)
    if kind == "rectangle" and cells > MAX_CELLS:
        raise ctx.fail("mesh.nx*mesh.ny", f"{nx}*{ny}", f"gives {cells} cells; at most {MAX_CELLS} are allowed")
    if kind == "box" and 6 * nx * ny * nz > MAX_CELLS:
        raise ctx.fail("mesh.nx*mesh.ny*mesh.nz", f"{nx}*{ny}*{nz}",
                       f"gives {6 * nx * ny * nz} cells; at most {MAX_CELLS} are allowed")
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
    return MeshConfig(kind, corners, nx, ny, diagonal, file, nz)


def to_toml(m: MeshConfig) -> dict:
    if m.kind == "gmsh":
        return {"kind": "gmsh", "file": m.file}
    out = dataclasses.asdict(m)
    out.pop("file")
    out.pop("diagonal" if m.kind == "box" else "nz")
    return out


def gmsh_dim(path: str) -> int:
    """Geometric dimension of a .msh file: 3 if any node has z != 0 (read once per version of the file: a tolerance
    run loads its scene a dozen times)."""
    try:
        st = os.stat(path)
        version = (os.path.realpath(path), st.st_mtime_ns, st.st_size)
    except OSError:
        version = (path, None, None)  # gmsh reports the problem
    return _gmsh_dim(*version)


@functools.lru_cache(maxsize=64)
def _gmsh_dim(path: str, mtime_ns: int | None, size: int | None) -> int:
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
