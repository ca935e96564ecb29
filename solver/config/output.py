"""[output]: where and how often results and checkpoints are written."""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass

from .fields import Ctx, boolean, check_keys, integer, names, need, string


@dataclass(frozen=True)
class OutputConfig:
    """Where and how often results are written (every=0: first and last only), and checkpoints
    every ``checkpoint_every`` steps (0: none)."""

    directory: str = "results"
    every: int = 1
    xdmf: bool = True
    checkpoint_every: int = 100


def parse(ctx: Ctx, t: dict, scene: dict) -> OutputConfig:
    t = check_keys(ctx, "output", t, names(OutputConfig))
    d = OutputConfig()
    directory = string(ctx, "output.directory", t.get("directory", d.directory))
    if not directory:
        raise ctx.fail("output.directory", directory, "must not be empty")
    every = integer(ctx, "output.every", t.get("every", d.every))
    need(ctx, "output.every", every, every >= 0, "must be >= 0 (0 writes the first and last levels only)")
    xdmf = boolean(ctx, "output.xdmf", t.get("xdmf", d.xdmf))
    ckpt = integer(ctx, "output.checkpoint_every", t.get("checkpoint_every", d.checkpoint_every))
    need(ctx, "output.checkpoint_every", ckpt, ckpt >= 0, "must be >= 0 (0: no checkpoints)")
    return OutputConfig(directory, every, xdmf, ckpt)


def to_toml(m: OutputConfig) -> dict:
    return dataclasses.asdict(m)
