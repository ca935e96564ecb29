"""Scene configuration: TOML -> validated, frozen dataclasses, one module per section.

Every key has the paper's value as default (docs/model.md §5, Example 1), so a scene
states only what differs. Unknown keys, wrong types, NaN/inf and values out of range
are rejected with a :class:`ConfigError` naming the file, the key, the value and what
is allowed. Nothing here touches dolfinx, so a scene can be checked before any
computation starts. See :mod:`solver.config.scene` for how sections are registered.
"""

from solver.errors import ConfigError

from .accuracy import AccuracyConfig
from .body_force import BodyForceConfig
from .boundary import LAWS, PAPER_BOUNDARIES, ROLES, SIDES, BoundaryConfig, table_at
from .damage import DamageConfig
from .discretization import DiscretizationConfig
from .material import MODELS, MaterialConfig
from .memory import KERNELS, MemoryConfig
from .mesh import DIAGONALS, MAX_CELLS, MeshConfig
from .output import OutputConfig
from .scene import SECTIONS, Config, apply_overrides, dumps, from_dict, load, merge, parse_override, replace, to_dict
from .solver import DAMAGE_SCHEMES, METHODS, SolverConfig
from .time import TimeConfig

__all__ = [
    "AccuracyConfig",
    "BodyForceConfig", "BoundaryConfig", "Config", "ConfigError", "DamageConfig", "DiscretizationConfig", "MaterialConfig",
    "MemoryConfig", "MeshConfig", "OutputConfig", "SolverConfig", "TimeConfig", "SECTIONS", "PAPER_BOUNDARIES", "ROLES",
    "LAWS", "SIDES", "MODELS",
    "KERNELS", "DIAGONALS", "MAX_CELLS", "METHODS", "DAMAGE_SCHEMES", "apply_overrides", "dumps", "from_dict",
    "load", "merge", "parse_override", "replace", "to_dict", "table_at",
]
