"""Validation helpers shared by the section modules: each names the key, the value and what is allowed."""

from __future__ import annotations

import dataclasses
import math
from typing import Any

from solver.errors import ConfigError


class Ctx:
    """Carries the scene file's name into every error message."""

    def __init__(self, source: str) -> None:
        self.source = source

    def fail(self, key: str, value: Any, allowed: str) -> ConfigError:
        return ConfigError(source=self.source, key=key, value=value, allowed=allowed)


def number(ctx: Ctx, key: str, v: Any) -> float:
    if isinstance(v, bool) or not isinstance(v, (int, float)):
        raise ctx.fail(key, v, "must be a number")
    v = float(v)
    if not math.isfinite(v):
        raise ctx.fail(key, v, "must be a finite number")
    return v


def integer(ctx: Ctx, key: str, v: Any) -> int:
    if isinstance(v, bool) or not isinstance(v, int):
        raise ctx.fail(key, v, "must be a whole number")
    return v


def boolean(ctx: Ctx, key: str, v: Any) -> bool:
    if not isinstance(v, bool):
        raise ctx.fail(key, v, "must be true or false")
    return v


def string(ctx: Ctx, key: str, v: Any, choices: tuple[str, ...] | None = None) -> str:
    if not isinstance(v, str):
        raise ctx.fail(key, v, "must be a string")
    if choices is not None and v not in choices:
        raise ctx.fail(key, v, "allowed: " + ", ".join(choices))
    return v


def vector(ctx: Ctx, key: str, v: Any, length: int | None = None) -> tuple[float, ...]:
    if not isinstance(v, list) or not v:
        raise ctx.fail(key, v, "must be a non-empty list of numbers")
    out = tuple(number(ctx, f"{key}[{i}]", x) for i, x in enumerate(v))
    if length is not None and len(out) != length:
        raise ctx.fail(key, v, f"must have {length} entries")
    return out


def check_keys(ctx: Ctx, section: str, table: Any, allowed: tuple[str, ...]) -> dict:
    if not isinstance(table, dict):
        raise ctx.fail(section, table, "must be a table [" + section + "]")
    for key in table:
        if key not in allowed:
            raise ctx.fail(f"{section}.{key}", table[key], "unknown key; allowed: " + ", ".join(allowed))
    return table


def names(cls: type) -> tuple[str, ...]:
    """The field names of a section's dataclass (its allowed keys)."""
    return tuple(f.name for f in dataclasses.fields(cls))


def need(ctx: Ctx, key: str, v: Any, ok: bool, allowed: str) -> None:
    if not ok:
        raise ctx.fail(key, v, allowed)
