"""Scene configuration: TOML -> validated, frozen dataclasses.

Every key has the paper's value as default (MODEL.md, Example 1), so a scene
states only what differs. Unknown keys, wrong types, NaN/inf and values out of
range are rejected with a :class:`ConfigError` naming the file, the key, the
value and what is allowed. Nothing here touches dolfinx, so a scene can be
checked before any computation starts.
"""

from __future__ import annotations

import dataclasses
import math
import tomllib
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

SIDES = ("left", "right", "bottom", "top")
ROLES = ("clamped", "traction", "contact")
DIAGONALS = ("right", "left", "right/left", "left/right", "crossed")
MODELS = ("plane_stress", "plane_strain", "3d")
KERNELS = ("none", "constant", "exponential", "tabulated")
METHODS = ("newton", "penalty_duality", "fixed_point")
DAMAGE_SCHEMES = ("explicit", "semi_implicit")
MAX_CELLS = 20_000_000  # refuse absurd meshes before allocating anything


class ConfigError(ValueError):
    """A scene is invalid; the message is one line meant for the user."""


# ----------------------------------------------------------------------------
# Sections
# ----------------------------------------------------------------------------


@dataclass(frozen=True)
class MeshConfig:
    """Built-in rectangle (corners, nx, ny, diagonal) or a gmsh ``.msh`` file."""

    kind: str = "rectangle"
    corners: tuple[tuple[float, float], tuple[float, float]] = ((0.0, 0.0), (1.0, 1.0))
    nx: int = 16
    ny: int = 16
    diagonal: str = "right"
    file: str = ""


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
        rows = self.traction
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
class MaterialConfig:
    """Isotropic elasticity A."""

    E: float = 100.0
    nu: float = 0.3
    model: str = "plane_stress"


@dataclass(frozen=True)
class MemoryConfig:
    """Kernel of G(t-s, eps, zeta) = zeta(s) g(t-s) Phi_L(A eps(u(s))).

    ``constant``: g = weights[0]; ``exponential``: g(s) = sum_i weights[i]
    exp(-s/times[i]) (a Prony series); ``tabulated``: g given by ``table``
    rows [s, g(s)], linear in between (keeps the full past); ``none``: no memory.
    ``rule``: the paper's left-rectangle sum, or the trapezoidal rule (implicit in the
    current level: Newton only, one factorization per step).
    """

    kernel: str = "constant"
    weights: tuple[float, ...] = (1.0,)
    times: tuple[float, ...] = ()
    table: tuple[tuple[float, float], ...] = ()
    L: float = 1000.0
    rule: str = "left"


@dataclass(frozen=True)
class DamageConfig:
    """Damage equation zeta' - kappa Lap zeta = phi(eps(u), zeta) (Fremond's source)."""

    enabled: bool = True
    kappa: float = 1e-2
    lambda1: float = 1e-2
    lambda2: float = 10.0
    lambda3: float = 0.0
    zeta_star: float = 0.01
    q_star: float = 1.0
    zeta0: float = 1.0
    clip: bool = True


@dataclass(frozen=True)
class TimeConfig:
    """Uniform steps k on [0, T]."""

    T: float = 1.0
    k: float = 0.01

    @property
    def steps(self) -> int:
        return int(round(self.T / self.k))


@dataclass(frozen=True)
class SolverConfig:
    """Solver settings: the displacement method (newton | penalty_duality | fixed_point) with its
    tolerance and iteration limit, the penalty-duality parameter (omega = value / mu), the
    damage scheme (explicit | semi_implicit), the linear solver and quadrature degrees."""

    rtol: float = 1e-10
    max_it: int = 25
    linear: str = "auto"
    method: str = "newton"
    penalty_duality_omega: float = 0.5
    damage_scheme: str = "explicit"
    quadrature_degree: int = 1
    damage_quadrature_degree: int = 2
    contact_quadrature_degree: int = 2
    petsc_options: tuple[tuple[str, str], ...] = ()


@dataclass(frozen=True)
class OutputConfig:
    """Where and how often results are written (every=0: first and last only), and checkpoints
    every ``checkpoint_every`` steps (0: none)."""

    directory: str = "results"
    every: int = 1
    xdmf: bool = True
    checkpoint_every: int = 100


@dataclass(frozen=True)
class Config:
    """A whole scene."""

    mesh: MeshConfig = field(default_factory=MeshConfig)
    boundaries: tuple[BoundaryConfig, ...] = ()
    material: MaterialConfig = field(default_factory=MaterialConfig)
    memory: MemoryConfig = field(default_factory=MemoryConfig)
    damage: DamageConfig = field(default_factory=DamageConfig)
    time: TimeConfig = field(default_factory=TimeConfig)
    solver: SolverConfig = field(default_factory=SolverConfig)
    output: OutputConfig = field(default_factory=OutputConfig)
    source: str = "<defaults>"

    @property
    def contact(self) -> tuple[BoundaryConfig, ...]:
        return tuple(b for b in self.boundaries if b.role == "contact")

    @property
    def tractions(self) -> tuple[BoundaryConfig, ...]:
        return tuple(b for b in self.boundaries if b.role == "traction")

    @property
    def clamped(self) -> tuple[BoundaryConfig, ...]:
        return tuple(b for b in self.boundaries if b.role == "clamped")


# The paper's Example 1 boundary (MODEL.md section 4), used when a scene gives none.
PAPER_BOUNDARIES: dict[str, dict[str, Any]] = {
    "left": {"role": "clamped"},
    "right": {"role": "traction", "traction": [-10.0, -10.0]},
    "bottom": {"role": "contact", "gap": 0.0, "mu": 1e-10},
}

# ----------------------------------------------------------------------------
# Parsing helpers
# ----------------------------------------------------------------------------


class _Ctx:
    """Carries the file name into error messages."""

    def __init__(self, source: str) -> None:
        self.source = source

    def fail(self, key: str, value: Any, allowed: str) -> ConfigError:
        return ConfigError(f"{self.source}: {key} = {_show(value)}: {allowed}")


def _show(value: Any) -> str:
    if isinstance(value, str):
        return repr(value)
    if isinstance(value, dict):
        return "{" + ", ".join(value) + "}"
    return str(value)


def _number(ctx: _Ctx, key: str, v: Any) -> float:
    if isinstance(v, bool) or not isinstance(v, (int, float)):
        raise ctx.fail(key, v, "must be a number")
    v = float(v)
    if not math.isfinite(v):
        raise ctx.fail(key, v, "must be a finite number")
    return v


def _integer(ctx: _Ctx, key: str, v: Any) -> int:
    if isinstance(v, bool) or not isinstance(v, int):
        raise ctx.fail(key, v, "must be a whole number")
    return v


def _boolean(ctx: _Ctx, key: str, v: Any) -> bool:
    if not isinstance(v, bool):
        raise ctx.fail(key, v, "must be true or false")
    return v


def _string(ctx: _Ctx, key: str, v: Any, choices: tuple[str, ...] | None = None) -> str:
    if not isinstance(v, str):
        raise ctx.fail(key, v, "must be a string")
    if choices is not None and v not in choices:
        raise ctx.fail(key, v, "allowed: " + ", ".join(choices))
    return v


def _vector(ctx: _Ctx, key: str, v: Any, length: int | None = None) -> tuple[float, ...]:
    if not isinstance(v, list) or not v:
        raise ctx.fail(key, v, "must be a non-empty list of numbers")
    out = tuple(_number(ctx, f"{key}[{i}]", x) for i, x in enumerate(v))
    if length is not None and len(out) != length:
        raise ctx.fail(key, v, f"must have {length} entries")
    return out


def _check_keys(ctx: _Ctx, section: str, table: Any, allowed: tuple[str, ...]) -> dict:
    if not isinstance(table, dict):
        raise ctx.fail(section, table, "must be a table [" + section + "]")
    for key in table:
        if key not in allowed:
            raise ctx.fail(f"{section}.{key}", table[key], "unknown key; allowed: " + ", ".join(allowed))
    return table


def _fields(cls: type) -> tuple[str, ...]:
    return tuple(f.name for f in dataclasses.fields(cls))


def _need(ctx: _Ctx, key: str, v: float, ok: bool, allowed: str) -> None:
    if not ok:
        raise ctx.fail(key, v, allowed)


# ----------------------------------------------------------------------------
# Sections
# ----------------------------------------------------------------------------


def _mesh(ctx: _Ctx, t: dict, base: Path) -> MeshConfig:
    t = _check_keys(ctx, "mesh", t, _fields(MeshConfig))
    d = MeshConfig()
    kind = _string(ctx, "mesh.kind", t.get("kind", d.kind), ("rectangle", "gmsh"))
    corners = d.corners
    if "corners" in t:
        c = t["corners"]
        if not isinstance(c, list) or len(c) != 2:
            raise ctx.fail("mesh.corners", c, "must be [[x0, y0], [x1, y1]]")
        p0 = _vector(ctx, "mesh.corners[0]", c[0], 2)
        p1 = _vector(ctx, "mesh.corners[1]", c[1], 2)
        if not (p1[0] > p0[0] and p1[1] > p0[1]):
            raise ctx.fail("mesh.corners", c, "need x1 > x0 and y1 > y0")
        corners = (p0, p1)  # type: ignore[assignment]
    nx = _integer(ctx, "mesh.nx", t.get("nx", d.nx))
    ny = _integer(ctx, "mesh.ny", t.get("ny", d.ny))
    for key, n in (("mesh.nx", nx), ("mesh.ny", ny)):
        _need(ctx, key, n, n >= 1, "must be at least 1")
    cells = nx * ny * (4 if t.get("diagonal") == "crossed" else 2)
    if kind == "rectangle" and cells > MAX_CELLS:
        raise ctx.fail("mesh.nx*mesh.ny", f"{nx}*{ny}", f"gives {cells} cells; at most {MAX_CELLS} are allowed")
    diagonal = _string(ctx, "mesh.diagonal", t.get("diagonal", d.diagonal), DIAGONALS)
    file = ""
    if kind == "gmsh":
        if "file" not in t:
            raise ctx.fail("mesh.file", "<missing>", "a gmsh scene needs mesh.file")
        file = _string(ctx, "mesh.file", t["file"])
        path = Path(file) if Path(file).is_absolute() else base / file
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


def _traction(ctx: _Ctx, key: str, v: Any, dim: int) -> tuple[tuple[float, ...], ...]:
    if not isinstance(v, list) or not v:
        raise ctx.fail(key, v, f"must be a vector of {dim} numbers or a table of rows [t, f_1..f_{dim}]")
    if not isinstance(v[0], list):
        return ((0.0, *_vector(ctx, key, v, dim)),)
    rows = tuple(_vector(ctx, f"{key}[{i}]", r, dim + 1) for i, r in enumerate(v))
    times = [r[0] for r in rows]
    if any(b < a for a, b in zip(times, times[1:])):
        raise ctx.fail(key, times, "table times must be sorted (a repeated time makes a jump)")
    if any(a == b == c for a, b, c in zip(times, times[1:], times[2:])):
        raise ctx.fail(key, times, "a time may appear at most twice (one jump)")
    return rows


def _boundaries(ctx: _Ctx, t: Any, mesh: MeshConfig, dim: int) -> tuple[BoundaryConfig, ...]:
    if t is None:
        if mesh.kind != "rectangle":
            raise ctx.fail("boundary", "<missing>", "a gmsh scene must name its boundary parts")
        t = PAPER_BOUNDARIES
    if not isinstance(t, dict) or not t:
        raise ctx.fail("boundary", t, "must hold at least one [boundary.NAME] table")
    out = []
    allowed = ("role", "side", "interval", "traction", "gap", "mu")
    for name, b in t.items():
        sec = f"boundary.{name}"
        b = _check_keys(ctx, sec, b, allowed)
        if "role" not in b:
            raise ctx.fail(f"{sec}.role", "<missing>", "allowed: " + ", ".join(ROLES))
        role = _string(ctx, f"{sec}.role", b["role"], ROLES)
        per_role = {"clamped": (), "traction": ("traction",), "contact": ("gap", "mu")}
        for key in ("traction", "gap", "mu"):
            if key in b and key not in per_role[role]:
                raise ctx.fail(f"{sec}.{key}", b[key], f"not used by role '{role}'")
        side, interval = "", None
        if mesh.kind == "rectangle":
            side = _string(ctx, f"{sec}.side", b.get("side", name), SIDES)
            if "interval" in b:
                iv = _vector(ctx, f"{sec}.interval", b["interval"], 2)
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
            traction = _traction(ctx, f"{sec}.traction", b["traction"], dim)
        gap = _number(ctx, f"{sec}.gap", b.get("gap", 0.0))
        mu = _number(ctx, f"{sec}.mu", b.get("mu", 1e-10))
        _need(ctx, f"{sec}.mu", mu, mu > 0, "must be > 0 (deformability of the foundation)")
        out.append(BoundaryConfig(name, role, side, interval, traction, gap, mu))
    if not any(b.role == "clamped" for b in out):
        raise ctx.fail("boundary", {b.name: 0 for b in out}, "needs a part with role = 'clamped' (else the body can float)")
    if mesh.kind == "rectangle":
        _check_overlaps(ctx, out, mesh)
    return tuple(out)


def _check_overlaps(ctx: _Ctx, parts: list[BoundaryConfig], mesh: MeshConfig) -> None:
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


def _material(ctx: _Ctx, t: dict, dim: int) -> MaterialConfig:
    t = _check_keys(ctx, "material", t, _fields(MaterialConfig))
    d = MaterialConfig()
    E = _number(ctx, "material.E", t.get("E", d.E))
    nu = _number(ctx, "material.nu", t.get("nu", d.nu))
    model = _string(ctx, "material.model", t.get("model", d.model), MODELS)
    _need(ctx, "material.E", E, E > 0, "must be > 0")
    if model == "plane_stress":
        _need(ctx, "material.nu", nu, -1 < nu < 1, "must be in (-1, 1) for plane stress")
    else:
        _need(ctx, "material.nu", nu, -1 < nu < 0.5, f"must be in (-1, 0.5) for {model}")
    if (model == "3d") != (dim == 3):
        raise ctx.fail("material.model", model, f"does not fit a {dim}-D mesh")
    return MaterialConfig(E, nu, model)


def _memory(ctx: _Ctx, t: dict) -> MemoryConfig:
    t = _check_keys(ctx, "memory", t, _fields(MemoryConfig))
    d = MemoryConfig()
    kernel = _string(ctx, "memory.kernel", t.get("kernel", d.kernel), KERNELS)
    rule = _string(ctx, "memory.rule", t.get("rule", d.rule), ("left", "trapezoid"))
    if rule == "trapezoid" and kernel not in ("constant", "exponential"):
        raise ctx.fail("memory.rule", rule, "the trapezoidal rule is for constant and exponential kernels")
    L = _number(ctx, "memory.L", t.get("L", d.L))
    _need(ctx, "memory.L", L, L > 0, "must be > 0")
    allowed = {
        "none": (),
        "constant": ("weights",),
        "exponential": ("weights", "times"),
        "tabulated": ("table",),
    }[kernel]
    for key in ("weights", "times", "table"):
        if key in t and key not in allowed:
            raise ctx.fail(f"memory.{key}", t[key], f"not used by kernel '{kernel}'")
    weights: tuple[float, ...] = ()
    times: tuple[float, ...] = ()
    table: tuple[tuple[float, float], ...] = ()
    if kernel == "constant":
        weights = _vector(ctx, "memory.weights", t.get("weights", [1.0]), 1)
    elif kernel == "exponential":
        for key in ("weights", "times"):
            if key not in t:
                raise ctx.fail(f"memory.{key}", "<missing>", "an exponential kernel needs weights and times")
        weights = _vector(ctx, "memory.weights", t["weights"])
        times = _vector(ctx, "memory.times", t["times"], len(weights))
        for i, tau in enumerate(times):
            _need(ctx, f"memory.times[{i}]", tau, tau > 0, "time constants must be > 0")
    elif kernel == "tabulated":
        if "table" not in t or not isinstance(t["table"], list) or len(t["table"]) < 2:
            raise ctx.fail("memory.table", t.get("table", "<missing>"), "needs at least two rows [s, g(s)]")
        table = tuple(_vector(ctx, f"memory.table[{i}]", r, 2) for i, r in enumerate(t["table"]))  # type: ignore[misc]
        s = [r[0] for r in table]
        if s[0] != 0 or any(b <= a for a, b in zip(s, s[1:])):
            raise ctx.fail("memory.table", s, "s must start at 0 and increase strictly")
    return MemoryConfig(kernel, weights, times, table, L, rule)


def _damage(ctx: _Ctx, t: dict) -> DamageConfig:
    t = _check_keys(ctx, "damage", t, _fields(DamageConfig))
    d = DamageConfig()
    v = {f: t.get(f, getattr(d, f)) for f in _fields(DamageConfig)}
    enabled = _boolean(ctx, "damage.enabled", v["enabled"])
    clip = _boolean(ctx, "damage.clip", v["clip"])
    num = {f: _number(ctx, f"damage.{f}", v[f]) for f in _fields(DamageConfig) if f not in ("enabled", "clip")}
    _need(ctx, "damage.kappa", num["kappa"], num["kappa"] >= 0, "must be >= 0")
    _need(ctx, "damage.zeta_star", num["zeta_star"], 0 < num["zeta_star"] < 1, "must be in (0, 1)")
    _need(ctx, "damage.zeta0", num["zeta0"], num["zeta_star"] <= num["zeta0"] <= 1, f"must be in [zeta_star = {num['zeta_star']}, 1]")
    _need(ctx, "damage.q_star", num["q_star"], num["q_star"] > 0, "must be > 0")
    for key in ("lambda1", "lambda2", "lambda3"):
        _need(ctx, f"damage.{key}", num[key], num[key] >= 0, "must be >= 0")
    return DamageConfig(enabled=enabled, clip=clip, **num)


def _time(ctx: _Ctx, t: dict) -> TimeConfig:
    t = _check_keys(ctx, "time", t, _fields(TimeConfig))
    d = TimeConfig()
    T = _number(ctx, "time.T", t.get("T", d.T))
    k = _number(ctx, "time.k", t.get("k", d.k))
    _need(ctx, "time.T", T, T > 0, "must be > 0")
    _need(ctx, "time.k", k, k > 0, "must be > 0")
    _need(ctx, "time.k", k, k <= T, f"must be <= time.T = {T}")
    n = T / k
    if abs(n - round(n)) > 1e-9 * max(1.0, n):
        raise ctx.fail("time.k", k, f"must divide time.T = {T} into a whole number of steps (T/k = {n:.6g})")
    if round(n) > 10_000_000:
        raise ctx.fail("time.k", k, f"gives {round(n)} steps; at most 10000000 are allowed")
    return TimeConfig(T, k)


def _solver(ctx: _Ctx, t: dict) -> SolverConfig:
    t = _check_keys(ctx, "solver", t, _fields(SolverConfig))
    d = SolverConfig()
    rtol = _number(ctx, "solver.rtol", t.get("rtol", d.rtol))
    _need(ctx, "solver.rtol", rtol, 0 < rtol < 1, "must be in (0, 1)")
    max_it = _integer(ctx, "solver.max_it", t.get("max_it", d.max_it))
    _need(ctx, "solver.max_it", max_it, max_it >= 1, "must be >= 1")
    linear = _string(ctx, "solver.linear", t.get("linear", d.linear), ("auto", "petsc", "mumps", "redundant"))
    method = _string(ctx, "solver.method", t.get("method", d.method), METHODS)
    omega = _number(ctx, "solver.penalty_duality_omega", t.get("penalty_duality_omega", d.penalty_duality_omega))
    _need(ctx, "solver.penalty_duality_omega", omega, omega > 0, "must be > 0 (omega = value / mu)")
    damage_scheme = _string(ctx, "solver.damage_scheme", t.get("damage_scheme", d.damage_scheme), DAMAGE_SCHEMES)
    degs = {}
    for key in ("quadrature_degree", "damage_quadrature_degree", "contact_quadrature_degree"):
        degs[key] = _integer(ctx, f"solver.{key}", t.get(key, getattr(d, key)))
        _need(ctx, f"solver.{key}", degs[key], 1 <= degs[key] <= 10, "must be in 1..10")
    opts = t.get("petsc_options", {})
    if not isinstance(opts, dict):
        raise ctx.fail("solver.petsc_options", opts, "must be a table of PETSc option = value")
    popts = []
    for key, val in opts.items():
        if isinstance(val, dict) or isinstance(val, list):
            raise ctx.fail(f"solver.petsc_options.{key}", val, "must be a string, number or boolean")
        if isinstance(val, float) and not math.isfinite(val):
            raise ctx.fail(f"solver.petsc_options.{key}", val, "must be finite")
        sval = ("true" if val else "false") if isinstance(val, bool) else str(val)
        popts.append((str(key), sval))
    return SolverConfig(rtol, max_it, linear, method, omega, damage_scheme, degs["quadrature_degree"],
                        degs["damage_quadrature_degree"],
                        degs["contact_quadrature_degree"], tuple(popts))


def _output(ctx: _Ctx, t: dict) -> OutputConfig:
    t = _check_keys(ctx, "output", t, _fields(OutputConfig))
    d = OutputConfig()
    directory = _string(ctx, "output.directory", t.get("directory", d.directory))
    if not directory:
        raise ctx.fail("output.directory", directory, "must not be empty")
    every = _integer(ctx, "output.every", t.get("every", d.every))
    _need(ctx, "output.every", every, every >= 0, "must be >= 0 (0 writes the first and last levels only)")
    xdmf = _boolean(ctx, "output.xdmf", t.get("xdmf", d.xdmf))
    ckpt = _integer(ctx, "output.checkpoint_every", t.get("checkpoint_every", d.checkpoint_every))
    _need(ctx, "output.checkpoint_every", ckpt, ckpt >= 0, "must be >= 0 (0: no checkpoints)")
    return OutputConfig(directory, every, xdmf, ckpt)


SECTIONS = ("mesh", "boundary", "material", "memory", "damage", "time", "solver", "output")


def _gmsh_dim(path: str) -> int:
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


def from_dict(data: dict, source: str = "<dict>", base: Path | None = None) -> Config:
    """Validate a parsed TOML document and build a :class:`Config`."""
    ctx = _Ctx(source)
    if not isinstance(data, dict):
        raise ctx.fail("<document>", data, "must be a TOML table")
    for key in data:
        if key not in SECTIONS:
            raise ctx.fail(key, data[key], "unknown section; allowed: " + ", ".join(SECTIONS))
    base = base or Path.cwd()
    mesh = _mesh(ctx, data.get("mesh", {}), base)
    dim = 2
    if mesh.kind == "gmsh":
        dim = _gmsh_dim(mesh.file)
    cfg = Config(
        mesh=mesh,
        boundaries=_boundaries(ctx, data.get("boundary"), mesh, dim),
        material=_material(ctx, data.get("material", {}), dim),
        memory=_memory(ctx, data.get("memory", {})),
        damage=_damage(ctx, data.get("damage", {})),
        time=_time(ctx, data.get("time", {})),
        solver=_solver(ctx, data.get("solver", {})),
        output=_output(ctx, data.get("output", {})),
        source=source,
    )
    if cfg.memory.rule == "trapezoid" and cfg.solver.method != "newton" and cfg.contact:
        raise ctx.fail("memory.rule", "trapezoid", f"needs solver.method = 'newton' (not {cfg.solver.method!r})")
    return cfg


def parse_override(item: str) -> tuple[list[str], Any]:
    """Parse ``section.key=value`` (value in TOML syntax; bare words are strings)."""
    if "=" not in item:
        raise ConfigError(f"--set {item!r}: expected section.key=value")
    key, raw = item.split("=", 1)
    path = key.strip().split(".")
    if len(path) < 2 or not all(path):
        raise ConfigError(f"--set {item!r}: the key must be section.key (e.g. mesh.nx=32)")
    try:
        value = tomllib.loads(f"v = {raw.strip()}")["v"]
    except tomllib.TOMLDecodeError:
        value = raw.strip()
    return path, value


def apply_overrides(data: dict, overrides: list[str]) -> dict:
    """Apply ``--set`` overrides to a parsed document (before validation)."""
    for item in overrides:
        path, value = parse_override(item)
        node = data
        for part in path[:-1]:
            if part not in node:
                node[part] = {}
            node = node[part]
            if not isinstance(node, dict):
                raise ConfigError(f"--set {item!r}: {part} is not a table")
        node[path[-1]] = value
    return data


def load(path: str | Path, overrides: list[str] | None = None) -> Config:
    """Read, override and validate a scene file."""
    path = Path(path)
    if not path.is_file():
        raise ConfigError(f"{path}: no such scene file")
    text = path.read_bytes()
    try:
        data = tomllib.loads(text.decode("utf-8"))
    except UnicodeDecodeError:
        raise ConfigError(f"{path}: not a text (UTF-8) file") from None
    except tomllib.TOMLDecodeError as exc:
        raise ConfigError(f"{path}: not valid TOML ({exc})") from None
    if not data:
        raise ConfigError(f"{path}: the scene file is empty (a scene needs at least one section)")
    data = apply_overrides(data, overrides or [])
    return from_dict(data, source=str(path), base=path.parent.resolve())


# ----------------------------------------------------------------------------
# Writing the resolved scene
# ----------------------------------------------------------------------------


def _toml_value(v: Any) -> str:
    if isinstance(v, bool):
        return "true" if v else "false"
    if isinstance(v, int):
        return str(v)
    if isinstance(v, float):
        return repr(v)
    if isinstance(v, str):
        return '"' + v.replace("\\", "\\\\").replace('"', '\\"') + '"'
    if isinstance(v, (list, tuple)):
        return "[" + ", ".join(_toml_value(x) for x in v) + "]"
    raise TypeError(type(v))


def to_dict(cfg: Config) -> dict:
    """The fully resolved scene as a TOML-shaped dictionary (round-trips through from_dict)."""
    out: dict[str, Any] = {}
    m = dataclasses.asdict(cfg.mesh)
    if cfg.mesh.kind == "rectangle":
        m.pop("file")
    else:
        m = {"kind": "gmsh", "file": cfg.mesh.file}
    out["mesh"] = m
    out["boundary"] = {}
    for b in cfg.boundaries:
        entry: dict[str, Any] = {"role": b.role}
        if b.side:
            entry["side"] = b.side
        if b.interval is not None:
            entry["interval"] = list(b.interval)
        if b.role == "traction":
            entry["traction"] = [list(r) for r in b.traction]
        if b.role == "contact":
            entry["gap"], entry["mu"] = b.gap, b.mu
        out["boundary"][b.name] = entry
    out["material"] = dataclasses.asdict(cfg.material)
    mem = dataclasses.asdict(cfg.memory)
    keep = {"none": (), "constant": ("weights",), "exponential": ("weights", "times"), "tabulated": ("table",)}
    for key in ("weights", "times", "table"):
        if key not in keep[cfg.memory.kernel]:
            mem.pop(key)
    out["memory"] = mem
    out["damage"] = dataclasses.asdict(cfg.damage)
    out["time"] = dataclasses.asdict(cfg.time)
    s = dataclasses.asdict(cfg.solver)
    s["petsc_options"] = dict(cfg.solver.petsc_options)
    out["solver"] = s
    out["output"] = dataclasses.asdict(cfg.output)
    return out


def dumps(cfg: Config) -> str:
    """TOML text of the resolved scene."""
    lines = [f"# resolved scene (from {cfg.source})"]

    def table(name: str, t: dict) -> None:
        lines.append(f"\n[{name}]")
        subtables = []
        for key, v in t.items():
            if isinstance(v, dict):
                subtables.append((key, v))
            else:
                lines.append(f"{key} = {_toml_value(v)}")
        for key, v in subtables:
            lines.append(f"\n[{name}.{key}]")
            for k2, v2 in v.items():
                lines.append(f'"{k2}" = {_toml_value(v2)}' if name == "solver" else f"{k2} = {_toml_value(v2)}")

    for name, t in to_dict(cfg).items():
        if name == "boundary":
            for bname, b in t.items():
                table(f"boundary.{bname}", b)
        else:
            table(name, t)
    return "\n".join(lines) + "\n"
