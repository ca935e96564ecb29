"""[body_force]: the volume force f0(t) of the model (docs/model.md §1), constant or a table in time."""

from __future__ import annotations

from dataclasses import dataclass

from .boundary import Table, table_at, time_table
from .fields import Ctx, check_keys
from .tables import DataTable


@dataclass(frozen=True)
class BodyForceConfig:
    """f0 = ``f``: rows [t, f_x, f_y(, f_z)] linear in t (one row: constant), inline or from a CSV file
    ({file, columns}); empty: no body force."""

    f: Table = ()

    def at(self, t: float) -> tuple[float, ...]:
        """f0 at time ``t`` (left-continuous at jumps)."""
        return table_at(self.f, t)


def parse(ctx: Ctx, t: dict, scene: dict) -> BodyForceConfig:
    t = check_keys(ctx, "body_force", t, ("f",))
    if "f" not in t:
        return BodyForceConfig()
    return BodyForceConfig(time_table(ctx, "body_force.f", t["f"], scene["dim"], scene["base"]))


def to_toml(m: BodyForceConfig) -> dict:
    if not m.f:
        return {}
    if len(m.f) == 1 and m.f[0][0] == 0.0 and not isinstance(m.f, DataTable):
        return {"f": list(m.f[0][1:])}
    return {"f": m.f}  # the rows (a file's stay a DataTable: the resolved scene refers to its data)
