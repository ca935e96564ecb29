"""[damage]: the damage equation and Fremond's source (docs/model.md §1, §2)."""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass

from solver.errors import ConfigError
from solver.laws.damage import FremondSource

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

    @property
    def law(self) -> FremondSource:
        """Fremond's source phi with this section's parameters (the law the damage step assembles)."""
        return FremondSource(self.lambda1, self.lambda2, self.lambda3, self.zeta_star, self.q_star)


def parse(ctx: Ctx, t: dict, scene: dict) -> DamageConfig:
    t = check_keys(ctx, "damage", t, names(DamageConfig))
    d = DamageConfig()
    v = {f: t.get(f, getattr(d, f)) for f in names(DamageConfig)}
    enabled = boolean(ctx, "damage.enabled", v["enabled"])
    clip = boolean(ctx, "damage.clip", v["clip"])
    num = {f: number(ctx, f"damage.{f}", v[f]) for f in names(DamageConfig) if f not in ("enabled", "clip")}
    need(ctx, "damage.kappa", num["kappa"], num["kappa"] >= 0, "must be >= 0")
    try:  # the law checks its own parameters
        FremondSource(num["lambda1"], num["lambda2"], num["lambda3"], num["zeta_star"], num["q_star"])
    except ConfigError as exc:
        raise ctx.fail(f"damage.{exc.key}", exc.value, exc.allowed) from None
    need(ctx, "damage.zeta0", num["zeta0"], num["zeta_star"] <= num["zeta0"] <= 1,
         f"must be in [zeta_star = {num['zeta_star']}, 1]")
    return DamageConfig(enabled=enabled, clip=clip, **num)


def to_toml(m: DamageConfig) -> dict:
    return dataclasses.asdict(m)
