"""The command line's check of a tolerance against ``--set`` overrides: what the planner chooses cannot be set."""

from __future__ import annotations

# the scene keys a tolerance decides itself (mesh size, step, degrees, order)
CHOSEN_KEYS = ("mesh.nx", "mesh.ny", "mesh.nz", "time.k", "discretization.u_degree", "discretization.zeta_degree",
               "time.order")


def contradicting(overrides: list[str]) -> list[str]:
    """The ``--set`` overrides (``key=value``) a tolerance decides itself."""
    return [o for o in overrides if o.split("=", 1)[0].strip() in CHOSEN_KEYS]
