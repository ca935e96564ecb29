"""A whole scene: the registry of sections, reading TOML, ``--set`` overrides, writing it back.

A section is one module with a frozen dataclass, ``parse(ctx, table, scene)`` and
``to_toml(value)``; :data:`SECTIONS` lists them in parse order (a section may read the
ones before it, and ``scene["dim"]``). Adding a section means adding its module and one
row here.
"""

from __future__ import annotations

import copy
import dataclasses
import hashlib
import re
import tomllib
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, NamedTuple

import tomlkit

from solver.errors import ConfigError

from . import accuracy, body_force, boundary, damage, discretization, material, memory, mesh, output, solver, time, tomlread
from .accuracy import AccuracyConfig
from .body_force import BodyForceConfig
from .boundary import BoundaryConfig
from .damage import DamageConfig
from .discretization import DiscretizationConfig
from .fields import Ctx
from .material import MaterialConfig
from .memory import MemoryConfig
from .mesh import MeshConfig
from .output import OutputConfig
from .solver import SolverConfig
from .tables import DataTable, reference, unchanged
from .time import TimeConfig


class Section(NamedTuple):
    """A TOML table, the Config field it fills, and its module's parse and to_toml."""

    key: str
    attr: str
    parse: Callable[[Ctx, Any, dict], Any]
    to_toml: Callable[[Any], dict]
    missing: Any = None  # what parse receives when the table is absent ({}: all defaults)


SECTIONS: tuple[Section, ...] = (
    Section("mesh", "mesh", mesh.parse, mesh.to_toml, {}),
    Section("boundary", "boundaries", boundary.parse, boundary.to_toml, None),
    Section("body_force", "body_force", body_force.parse, body_force.to_toml, {}),
    Section("material", "material", material.parse, material.to_toml, {}),
    Section("discretization", "discretization", discretization.parse, discretization.to_toml, {}),
    Section("time", "time", time.parse, time.to_toml, {}),
    Section("memory", "memory", memory.parse, memory.to_toml, {}),
    Section("damage", "damage", damage.parse, damage.to_toml, {}),
    Section("solver", "solver", solver.parse, solver.to_toml, {}),
    Section("output", "output", output.parse, output.to_toml, {}),
    Section("accuracy", "accuracy", accuracy.parse, accuracy.to_toml, {}),
)


@dataclass(frozen=True)
class Config:
    """A whole scene."""

    mesh: MeshConfig = field(default_factory=MeshConfig)
    boundaries: tuple[BoundaryConfig, ...] = ()
    body_force: BodyForceConfig = field(default_factory=BodyForceConfig)
    material: MaterialConfig = field(default_factory=MaterialConfig)
    discretization: DiscretizationConfig = field(default_factory=DiscretizationConfig)
    memory: MemoryConfig = field(default_factory=MemoryConfig)
    damage: DamageConfig = field(default_factory=DamageConfig)
    time: TimeConfig = field(default_factory=TimeConfig)
    solver: SolverConfig = field(default_factory=SolverConfig)
    output: OutputConfig = field(default_factory=OutputConfig)
    accuracy: AccuracyConfig = field(default_factory=AccuracyConfig)
    source: str = "<defaults>"
    # the document as given (file and --set, before defaults are resolved) and its directory: what replace() edits
    document: dict | None = field(default=None, compare=False, repr=False)
    base: Path | None = field(default=None, compare=False, repr=False)

    @property
    def dim(self) -> int:
        """Geometric dimension of the scene (the material model says it: '3d' or a plane model)."""
        return 3 if self.material.model == "3d" else 2

    @property
    def contact(self) -> tuple[BoundaryConfig, ...]:
        return tuple(b for b in self.boundaries if b.role == "contact")

    @property
    def tractions(self) -> tuple[BoundaryConfig, ...]:
        return tuple(b for b in self.boundaries if b.role == "traction")

    @property
    def clamped(self) -> tuple[BoundaryConfig, ...]:
        return tuple(b for b in self.boundaries if b.role == "clamped")

    @property
    def dirichlet(self) -> tuple[BoundaryConfig, ...]:
        """Parts that prescribe displacements: clamped and displacement."""
        return tuple(b for b in self.boundaries if b.dirichlet)

    def replace(self, changes: dict, label: str = "replace()") -> Config:
        """This scene with ``changes`` (TOML-shaped, e.g. ``{"time": {"k": 0.005}}``), validated as a file is
        (:func:`replace`)."""
        return replace(self, changes, label)


def from_dict(data: dict, source: str = "<dict>", base: Path | None = None) -> Config:
    """Validate a parsed TOML document and build a :class:`Config`."""
    ctx = Ctx(source)
    if not isinstance(data, dict):
        raise ctx.fail("<document>", data, "must be a TOML table")
    known = [s.key for s in SECTIONS]
    for key in data:
        if key not in known:
            raise ctx.fail(key, data[key], "unknown section; allowed: " + ", ".join(known))
    scene: dict[str, Any] = {"base": base or Path.cwd(), "dim": 2}
    for s in SECTIONS:
        scene[s.key] = s.parse(ctx, data.get(s.key, s.missing), scene)
        if s.key == "mesh":
            m = scene["mesh"]
            scene["dim"] = mesh.gmsh_dim(m.file) if m.kind == "gmsh" else m.dim
    return Config(**{s.attr: scene[s.key] for s in SECTIONS}, source=source, document=_copy(data), base=base)


def _copy(v: Any) -> Any:
    """A deep copy of a parsed document (tables of rows copied row by row: copy.deepcopy takes 0.3 s for 10⁵ rows)."""
    if isinstance(v, dict):
        return {k: _copy(x) for k, x in v.items()}
    if isinstance(v, DataTable):
        return v  # the scene reader's big tables: immutable
    if isinstance(v, list):
        if v and all(type(r) is list for r in v) and all(type(x) in (float, int) for x in v[0]):
            if all(type(x) in (float, int) for r in v for x in r):
                return [r[:] for r in v]
        return [_copy(x) for x in v]
    return copy.deepcopy(v)


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
    try:
        if not path.is_file():
            raise ConfigError(f"{path}: no such scene file")
        text = path.read_bytes()
    except OSError as exc:  # a name too long, a directory without permission (found by the fuzzer)
        raise ConfigError(f"{str(path)[:200]}: cannot read the scene file ({exc.strerror or exc})") from None
    try:
        data = tomlread.loads(text.decode("utf-8"))
    except UnicodeDecodeError:
        raise ConfigError(f"{path}: not a text (UTF-8) file") from None
    except tomllib.TOMLDecodeError as exc:
        raise ConfigError(f"{path}: not valid TOML ({exc})") from None
    if not data:
        raise ConfigError(f"{path}: the scene file is empty (a scene needs at least one section)")
    data = apply_overrides(data, overrides or [])
    try:
        return from_dict(data, source=str(path), base=path.parent.resolve())
    except ConfigError as exc:
        item = _override_of(exc.key, overrides or [])
        if item is None:
            raise
        # the value came from the command line, not the file: say so
        raise ConfigError(source=f"--set {item}", key=exc.key, value=exc.value, allowed=exc.allowed) from None


def _override_of(key: str, overrides: list[str]) -> str | None:
    """The last ``--set`` that wrote ``key`` (or a table holding it, or a key inside it), if any."""
    if not key:
        return None
    for item in reversed(overrides):
        path = ".".join(parse_override(item)[0])
        if path == key or key.startswith(path + ".") or path.startswith(key + "."):
            return item
    return None


def replace(cfg: Config, changes: dict, label: str = "replace()") -> Config:
    """``cfg`` with ``changes`` (TOML-shaped) merged into its document and validated by :func:`from_dict`: the same
    checks and one-line ConfigErrors as a scene file, their source ``"<cfg.source> (<label>)"``. The result keeps
    ``cfg.source`` and equals loading the file with the equivalent ``--set``.

    The document is the one given (``cfg.document``), not :func:`to_dict`'s resolved scene, where derived values
    are fixed (``memory.rule = 'auto'``, the quadrature degrees): a new ``time.order`` or degree re-derives them as
    in a file. A Config built without a document (by hand) falls back to :func:`to_dict`.
    """
    source = f"{cfg.source} ({label})"
    data = merge(to_dict(cfg) if cfg.document is None else cfg.document, changes, Ctx(source))
    return dataclasses.replace(from_dict(data, source=source, base=cfg.base), source=cfg.source)


def merge(data: dict, changes: dict, ctx: Ctx | None = None, prefix: str = "") -> dict:
    """``data`` with ``changes`` merged in, table by table (a new dict: neither argument is changed)."""
    ctx = ctx or Ctx("merge()")
    if not isinstance(changes, dict):
        raise ctx.fail(prefix.rstrip(".") or "<changes>", changes, "must be a table of changes")
    out = dict(data)
    for key, value in changes.items():
        if isinstance(value, dict):
            node = out.get(key, {})
            if not isinstance(node, dict):
                raise ctx.fail(prefix + key, node, "is not a table")
            out[key] = merge(node, value, ctx, f"{prefix}{key}.")
        else:
            out[key] = value
    return out


def to_dict(cfg: Config) -> dict:
    """The fully resolved scene as a TOML-shaped dictionary (round-trips through from_dict); tables inline."""
    return {s.key: _lists(s.to_toml(getattr(cfg, s.attr))) for s in SECTIONS}


Refer = Callable[[str, DataTable], Any]


def _lists(v: Any, refer: Refer | None = None, path: str = "") -> Any:
    """Tuples as lists, all the way down (what a TOML writer takes); with ``refer``, each table of rows (a
    :class:`DataTable`) is replaced by what ``refer(path, table)`` returns (its dotted key ``path``)."""
    if isinstance(v, DataTable):
        return refer(path, v) if refer is not None else v.array.tolist()
    if isinstance(v, dict):
        return {k: _lists(x, refer, f"{path}.{k}" if path else k) for k, x in v.items()}
    if isinstance(v, (list, tuple)):
        if v and all(type(r) is tuple for r in v) and all(type(x) is float for x in v[0]):
            return [list(r) for r in v]  # a table's rows (numbers only): one step, not one call per number
        return [_lists(x, refer, f"{path}.{i}") for i, x in enumerate(v)]
    return v


class _Inline(dict):
    """A table written inline ({file = ...}), not as a [section]."""


class _Verbatim(str):
    """A value's TOML text, written as it is (a big inline table as the scene gave it)."""


_BIG = 16  # tables of more rows are written by _array: tomlkit's Array.insert re-indexes the array per element


def _toml(data: dict) -> str:
    """TOML text of ``data`` in time linear in its size: tomlkit for the structure (arrays stay on one line), the
    tables of more than _BIG rows formatted here."""
    big: dict[str, list] = {}

    def cut(v: Any) -> Any:
        if isinstance(v, _Verbatim):
            mark = f"@@table-{len(big)}@@"
            big[mark] = v
            return mark
        if isinstance(v, _Inline):
            out = tomlkit.inline_table()
            out.update({k: cut(x) for k, x in v.items()})
            return out
        if isinstance(v, dict):
            return {k: cut(x) for k, x in v.items()}
        if isinstance(v, list):
            if len(v) > _BIG and all(isinstance(r, list) for r in v):
                mark = f"@@table-{len(big)}@@"
                big[mark] = v
                return mark
            return [cut(x) for x in v]
        return v

    text = tomlkit.dumps(cut(data))
    for mark, rows in big.items():
        text = text.replace(f'"{mark}"', rows if isinstance(rows, _Verbatim) else _array(rows), 1)
    return text


def _array(rows: list) -> str:
    """A table of rows of numbers as a one-line TOML array (Python's repr of a finite float is a TOML float)."""
    return "[" + ", ".join("[" + ", ".join(map(repr, r)) + "]" for r in rows) + "]"


def dumps(cfg: Config) -> str:
    """TOML text of the resolved scene, every table inline (written with tomlkit: arrays stay on one line; big
    tables by hand, in linear time)."""
    return f"# resolved scene (from {cfg.source})\n" + _toml(to_dict(cfg))


def fingerprint(cfg: Config) -> str:
    """The resolved scene as :func:`dumps` writes it, but each table of more than _BIG rows as its number of rows and
    the SHA-256 of its numbers: what identifies a scene (a checkpoint's), in milliseconds for 10⁵-row tables."""
    def digest(path: str, table: DataTable) -> Any:
        if len(table) <= _BIG:
            return [list(r) for r in table]
        return {"rows": len(table), "sha256": hashlib.sha256(table.array.tobytes()).hexdigest()}

    data = {s.key: _lists(s.to_toml(getattr(cfg, s.attr)), digest, s.key) for s in SECTIONS}
    return f"# resolved scene (from {cfg.source})\n" + _toml(data)


TABLES = "tables"  # where dumps_referring puts the tables read from files, beside the scene it writes


def dumps_referring(cfg: Config) -> tuple[str, dict[str, tuple[DataTable, bool]]]:
    """TOML text of the resolved scene in which each table read from a CSV file refers to a copy of it,
    ``{file = "tables/<key>.csv"}``, and those copies: {relative name: (rows, whether the file is copied as it is)}
    (written by :func:`solver.config.tables.write_copy`; a file changed since it was read is written from the rows
    the run uses). Tables given inline stay inline."""
    copies: dict[str, tuple[DataTable, bool]] = {}

    def refer(path: str, table: DataTable) -> dict:
        stem = f"{TABLES}/{re.sub(r'[^A-Za-z0-9._-]', '_', path)}"
        name, i = f"{stem}.csv", 1
        while name in copies:
            i += 1
            name = f"{stem}-{i}.csv"
        if table.file is None:  # given inline: stays inline (a big one as the scene wrote it)
            return _Verbatim(table.text) if table.text is not None else [list(r) for r in table]
        as_file = unchanged(table)
        copies[name] = (table, as_file)
        return _Inline(reference(table, name, as_file))

    data = {s.key: _lists(s.to_toml(getattr(cfg, s.attr)), refer, s.key) for s in SECTIONS}
    head = f"# resolved scene (from {cfg.source})\n"
    if copies:
        head += f"# the tables read from files are copied to {TABLES}/ beside this file\n"
    return head + _toml(data), copies
