"""[discretization]: polynomial degrees of the displacement and the damage (docs/model.md §3.1)."""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass

from .fields import Ctx, check_keys, integer, names, need

DEGREES = (1, 2)


@dataclass(frozen=True)
class DiscretizationConfig:
    """Lagrange degrees: 1 is the paper's P1; 2 gives P2 fields (u quadratic: eps(u) linear per cell)."""

    u_degree: int = 1
    zeta_degree: int = 1

    def memory_quadrature_degree(self) -> int:
        """The degree that integrates (zeta Phi_L(A eps(u)), eps(w)) exactly without truncation:
        2 (u_degree - 1) + zeta_degree (1 for P1/P1, 3 for P2 u with P1 zeta)."""
        return 2 * (self.u_degree - 1) + self.zeta_degree

    def contact_quadrature_degree(self) -> int:
        """Twice the degree of u_nu on a facet: the kink of p is inside a facet, so more points than exact."""
        return 2 * self.u_degree


def parse(ctx: Ctx, t: dict, scene: dict) -> DiscretizationConfig:
    t = check_keys(ctx, "discretization", t, names(DiscretizationConfig))
    d = DiscretizationConfig()
    out = {}
    for key in names(DiscretizationConfig):
        out[key] = integer(ctx, f"discretization.{key}", t.get(key, getattr(d, key)))
        need(ctx, f"discretization.{key}", out[key], out[key] in DEGREES, "allowed: 1, 2")
    return DiscretizationConfig(**out)


def to_toml(m: DiscretizationConfig) -> dict:
    return dataclasses.asdict(m)
