"""[output]: where and how often results and checkpoints are written, which fields and in what precision."""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass

from .fields import Ctx, boolean, check_keys, integer, names, need, number, string

# the fields a run can write (solver/io/fields.py says what each is)
FIELD_NAMES = ("displacement", "damage", "stress", "elastic_stress", "von_mises", "von_mises_elastic", "stress_zz",
               "elastic_stress_zz",  # these two: plane strain only (sigma_33), skipped elsewhere
               "contact_pressure", "gap", "penetration")  # vertex fields on Γ_C (zero off it); with contact only
# what a ParaView user needs to warp the body and colour it as the paper does; the two tensors
# (6 values per cell each) triple the bytes per level and are written only on request
DEFAULT_FIELDS = ("displacement", "damage", "von_mises", "von_mises_elastic")
PRECISIONS = ("double", "single")


@dataclass(frozen=True)
class OutputConfig:
    """Where and how often results are written (every=0: first and last only), which ``fields``
    (``damage`` only where the scene has damage, ``stress_zz``/``elastic_stress_zz`` only in plane strain) in
    which ``precision``, and checkpoints every
    ``checkpoint_every`` steps (0: none). ``times``: times in (0, T] an adaptive run (``time.adaptive``) lands on and
    writes, besides every ``every``-th level."""

    directory: str = "results"
    every: int = 1
    xdmf: bool = True
    fields: tuple[str, ...] = DEFAULT_FIELDS
    precision: str = "double"
    checkpoint_every: int = 100
    times: tuple[float, ...] = ()


def _fields(ctx: Ctx, v) -> tuple[str, ...]:
    allowed = "a non-empty list of field names from " + ", ".join(FIELD_NAMES)
    if not isinstance(v, list) or not v or not all(isinstance(x, str) for x in v):
        raise ctx.fail("output.fields", v, allowed)
    for x in v:
        need(ctx, "output.fields", x, x in FIELD_NAMES, "not a field; allowed: " + ", ".join(FIELD_NAMES))
    need(ctx, "output.fields", v, len(set(v)) == len(v), "names a field twice")
    return tuple(v)


def parse(ctx: Ctx, t: dict, scene: dict) -> OutputConfig:
    t = check_keys(ctx, "output", t, names(OutputConfig))
    d = OutputConfig()
    directory = string(ctx, "output.directory", t.get("directory", d.directory))
    if not directory:
        raise ctx.fail("output.directory", directory, "must not be empty")
    every = integer(ctx, "output.every", t.get("every", d.every))
    need(ctx, "output.every", every, every >= 0, "must be >= 0 (0 writes the first and last levels only)")
    xdmf = boolean(ctx, "output.xdmf", t.get("xdmf", d.xdmf))
    fields = _fields(ctx, t.get("fields", list(d.fields)))
    precision = string(ctx, "output.precision", t.get("precision", d.precision), PRECISIONS)
    ckpt = integer(ctx, "output.checkpoint_every", t.get("checkpoint_every", d.checkpoint_every))
    need(ctx, "output.checkpoint_every", ckpt, ckpt >= 0, "must be >= 0 (0: no checkpoints)")
    times = t.get("times", [])
    if not isinstance(times, list):
        raise ctx.fail("output.times", times, "must be a list of times in (0, time.T]")
    times = tuple(number(ctx, "output.times", v) for v in times)
    T = scene["time"].T
    need(ctx, "output.times", list(times), all(0.0 < v <= T for v in times), f"each must be in (0, time.T = {T}]")
    need(ctx, "output.times", list(times), not times or scene["time"].adaptive,
         "applies to adaptive steps only (time.adaptive = true; uniform steps write every output.every levels)")
    return OutputConfig(directory, every, xdmf, fields, precision, ckpt, tuple(sorted(times)))


def to_toml(m: OutputConfig) -> dict:
    out = dataclasses.asdict(m)
    if not m.times:
        del out["times"]
    return out
