"""[damage]: the damage equation and Fremond's source (docs/model.md §1, §2)."""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass

from .fields import Ctx, boolean, check_keys, names, need, number


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


def parse(ctx: Ctx, t: dict, scene: dict) -> DamageConfig:
    t = check_keys(ctx, "damage", t, names(DamageConfig))
    d = DamageConfig()
    v = {f: t.get(f, getattr(d, f)) for f in names(DamageConfig)}
    enabled = boolean(ctx, "damage.enabled", v["enabled"])
    clip = boolean(ctx, "damage.clip", v["clip"])
    num = {f: number(ctx, f"damage.{f}", v[f]) for f in names(DamageConfig) if f not in ("enabled", "clip")}
    need(ctx, "damage.kappa", num["kappa"], num["kappa"] >= 0, "must be >= 0")
    need(ctx, "damage.zeta_star", num["zeta_star"], 0 < num["zeta_star"] < 1, "must be in (0, 1)")
    need(ctx, "damage.zeta0", num["zeta0"], num["zeta_star"] <= num["zeta0"] <= 1,
         f"must be in [zeta_star = {num['zeta_star']}, 1]")
    need(ctx, "damage.q_star", num["q_star"], num["q_star"] > 0, "must be > 0")
    for key in ("lambda1", "lambda2", "lambda3"):
        need(ctx, f"damage.{key}", num[key], num[key] >= 0, "must be >= 0")
    return DamageConfig(enabled=enabled, clip=clip, **num)


def to_toml(m: DamageConfig) -> dict:
    return dataclasses.asdict(m)
