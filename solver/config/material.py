"""[material]: isotropic elasticity A (docs/model.md §2)."""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass

from .fields import Ctx, check_keys, names, need, number, string

MODELS = ("plane_stress", "plane_strain", "3d")


@dataclass(frozen=True)
class MaterialConfig:
    """Isotropic elasticity A."""

    E: float = 100.0
    nu: float = 0.3
    model: str = "plane_stress"


def parse(ctx: Ctx, t: dict, scene: dict) -> MaterialConfig:
    t = check_keys(ctx, "material", t, names(MaterialConfig))
    d = MaterialConfig()
    E = number(ctx, "material.E", t.get("E", d.E))
    nu = number(ctx, "material.nu", t.get("nu", d.nu))
    model = string(ctx, "material.model", t.get("model", d.model), MODELS)
    need(ctx, "material.E", E, E > 0, "must be > 0")
    if model == "plane_stress":
        need(ctx, "material.nu", nu, -1 < nu < 1, "must be in (-1, 1) for plane stress")
    else:
        need(ctx, "material.nu", nu, -1 < nu < 0.5, f"must be in (-1, 0.5) for {model}")
    dim = scene["dim"]
    if (model == "3d") != (dim == 3):
        raise ctx.fail("material.model", model, f"does not fit a {dim}-D mesh")
    return MaterialConfig(E, nu, model)


def to_toml(m: MaterialConfig) -> dict:
    return dataclasses.asdict(m)
