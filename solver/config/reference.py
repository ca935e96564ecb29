"""The scene-key reference: every key of every section, its type, default, allowed values and meaning.

Types and defaults are read from the section dataclasses, the allowed choices from the section
modules' constants, and only the one-line meaning is written here (:data:`MEANING`);
``tests/config/test_reference.py`` fails when a dataclass field has no line (or a line names a
key that is gone), so the page ``docs/reference/scene.md`` (written by :func:`markdown`) cannot
drift from the code.
"""

from __future__ import annotations

import dataclasses
import typing
from collections.abc import Iterator
from typing import NamedTuple

from . import accuracy, boundary, material, memory, mesh, output, solver
from .discretization import DEGREES
from .scene import SECTIONS, Config

# One line a key, "section.key" (boundary keys as "boundary.NAME.key").
MEANING: dict[str, str] = {
    "mesh.kind": "the mesh: a built-in `rectangle` (2-D) or `box` (3-D, tetrahedra), or `gmsh` (a `.msh` file)",
    "mesh.corners": "two opposite corners [[x0, y0(, z0)], [x1, y1(, z1)]] of the rectangle or box",
    "mesh.nx": "cells along x (built-in meshes)",
    "mesh.ny": "cells along y (built-in meshes)",
    "mesh.nz": "cells along z (box only)",
    "mesh.diagonal": "how the rectangle's squares are cut into triangles",
    "mesh.file": "the gmsh `.msh` file (kind = gmsh), relative to the scene file; its physical groups name the parts",
    "boundary.NAME.role": "what the part does: fixed, moved, loaded or in contact with the foundation",
    "boundary.NAME.side": "which side (rectangle) or face (box) the part is on; default: the table's NAME",
    "boundary.NAME.interval": "a sub-interval [a, b] of the side (rectangle) or a sub-rectangle [[a0, a1], [b0, b1]] "
                              "of the face (box); default: all of it",
    "boundary.NAME.traction": "surface traction f2 (role traction): a vector, or rows [t, f_x, f_y(, f_z)] linear in t"
                              " (inline, or a CSV file {file = \"load.csv\", columns = [...]})",
    "boundary.NAME.displacement": "prescribed u (role displacement): per component a number, a table of rows "
                                  "[t, value] (inline or {file, columns}), or \"free\"",
    "boundary.NAME.gap": "initial gap g to the foundation (role contact): a number, or rows [s, g] along gap_coordinate,"
                         " inline or from a CSV file: {file = \"profile.csv\", columns = [\"x\", \"g\"]} (columns by"
                         " header name or number from 1; the path relative to the scene file)",
    "boundary.NAME.gap_coordinate": "the coordinate (x, y or z) a tabulated gap is a function of",
    "boundary.NAME.gap_interpolation": "how a gap table is read between its rows: linear, or a C2 cubic spline for curved profiles",
    "boundary.NAME.obstacle": "an analytic rigid obstacle instead of a gap: {shape = plane, point, normal} or "
                              "{shape = circle | sphere, centre, radius}; g is the signed distance to it",
    "boundary.NAME.law": "the normal-compliance law p in -sigma_nu = p(u_nu - g)",
    "boundary.NAME.mu": "compliance of the linear law, p(r) = r_+ / mu (the paper's: 1e-10, nearly rigid)",
    "boundary.NAME.coefficient": "power law: p(r) = coefficient r_+^exponent",
    "boundary.NAME.exponent": "power law's exponent (>= 1)",
    "boundary.NAME.depth": "limited penetration: thickness of the soft layer before the stiff foundation",
    "boundary.NAME.mu_stiff": "limited penetration: compliance of the stiff foundation below the layer",
    "body_force.f": "body force f0: rows [t, f_x, f_y(, f_z)] linear in t (one row: constant), inline or "
                    "{file, columns}; empty: none",
    "material.E": "Young's modulus of the elasticity tensor A",
    "material.nu": "Poisson's ratio (< 0.5)",
    "material.model": "plane stress or plane strain (2-D), or 3d",
    "discretization.u_degree": "Lagrange degree of the displacement u",
    "discretization.zeta_degree": "Lagrange degree of the damage zeta",
    "time.T": "final time",
    "time.k": "time step (must divide T); with time.adaptive the first step",
    "time.adaptive": "choose the steps during the run for time.tolerance (docs/model.md §3.9)",
    "time.tolerance": "adaptive steps: target of the time error in the paper's norm (an equal error per step, docs/model.md §3.9)",
    "time.k_min": "adaptive steps: the smallest step (0: T 1e-9)",
    "time.k_max": "adaptive steps: the largest step (0: T)",
    "time.order": "1: the paper's scheme; 2: the second-order one (CN-AB2 damage, trapezoidal memory)",
    "memory.kernel": "the memory kernel g in G = zeta(s) g(t - s) Phi_L(A eps(u(s))); none: no memory",
    "memory.weights": "constant: g = weights[0]; exponential: the Prony weights",
    "memory.times": "exponential: the Prony time constants (> 0)",
    "memory.table": "tabulated: rows [s, g(s)], linear in between, constant after the last; inline or {file, "
                    "columns}; run as a sum of exponentials (kernel_tolerance)",
    "memory.coefficient": "power: c in g(s) = c s^-alpha (nonzero)",
    "memory.exponent": "power: alpha in g(s) = c s^-alpha, 0 < alpha < 1 (weakly singular: left rule only)",
    "memory.kernel_tolerance": "tabulated, power: the largest relative error |g~ - g| / |g| of the sum of exponentials "
                               "g~ that replaces g, at the lags the run evaluates (at most 64 terms)",
    "memory.L": "truncation level of Phi_L",
    "memory.rule": "quadrature of the memory integral (auto: left for order 1, trapezoid_extrapolated for order 2)",
    "damage.enabled": "solve the damage equation; false: zeta = zeta0 throughout",
    "damage.kappa": "damage diffusion kappa in zeta' - kappa Lap zeta = phi",
    "damage.lambda1": "Fremond's source: lambda1 (healing/threshold term)",
    "damage.lambda2": "Fremond's source: lambda2 (growth from the strain energy)",
    "damage.lambda3": "Fremond's source: lambda3",
    "damage.zeta_star": "lower bound zeta* of the damage (0 < zeta* < 1)",
    "damage.q_star": "the source's scale q* (the paper does not give it)",
    "damage.zeta0": "initial damage (1: undamaged)",
    "damage.clip": "clip the nodal damage to [zeta*, 1] after each step",
    "solver.rtol": "relative tolerance of the displacement iteration",
    "solver.max_it": "iteration limit of the displacement solve per level",
    "solver.linear": ("linear solver (auto: chosen on the mesh, the number of ranks and, in 3-D, the number of steps; "
                      "cholmod: SuiteSparse's Cholesky for the displacement, petsc where PETSc lacks it)"),
    "solver.method": "displacement method for the contact nonlinearity (auto: Newton until a level takes 8, then newton_condensed)",
    "solver.penalty_duality_omega": "penalty-duality parameter: omega = value / mu",
    "solver.damage_scheme": "time scheme of the damage equation",
    "solver.quadrature_degree": "quadrature degree of the memory terms (0: from the degrees)",
    "solver.damage_quadrature_degree": "quadrature degree of the damage source (0: from the degrees)",
    "solver.contact_quadrature_degree": "quadrature degree of the contact term (0: from the degrees)",
    "solver.contact_points": ("where the contact law acts on a facet: gauss (the Gauss points of "
                              "contact_quadrature_degree) or nodes (u's nodes, Newton-Cotes weights: a lumped contact)"),
    "solver.petsc_options": "extra PETSc options, a table option = value",
    "solver.newton_fallback": "re-solve a level plain Newton does not solve with a line-searched Newton",
    "output.directory": "results directory (the CLI's --output wins)",
    "output.every": "write every N-th level and the last (0: the first and last only)",
    "output.xdmf": "write the fields (solution.xdmf + fields/); false: the CSV time series only",
    "output.fields": "the fields written",
    "output.precision": "floating-point precision of the written fields",
    "output.checkpoint_every": "write checkpoint.h5 every N levels for --restart (0: never)",
    "output.times": "adaptive steps: times the run lands on and writes, besides every N-th level",
    "accuracy.tolerance": "accuracy on demand: the solver chooses mesh, step, degree and order for this error bound",
    "accuracy.relative": "tolerance relative to ||eps(u_0)||",
    "accuracy.space_share": "share of the tolerance given to the mesh (the rest to the step)",
    "accuracy.theta": "Dörfler marking fraction of the mesh refinement",
    "accuracy.max_dofs": "refuse plans above this many displacement dofs",
    "accuracy.degrees": "displacement degrees the planner may choose from",
    "accuracy.simplify": "leave out the memory term and the damage where together they change the answer by at most "
                         "a tenth of the tolerance (plan.json lists each ingredient's change)",
    "accuracy.time": "how the step is chosen: uniform (one step, by step doubling on pilot runs) or adaptive (the "
                     "run-time step controller, time.adaptive, with the time's share of the tolerance)",
}

# Allowed values that are a list of choices, from the section modules' constants.
CHOICES: dict[str, tuple] = {
    "mesh.kind": ("rectangle", "box", "gmsh"), "mesh.diagonal": mesh.DIAGONALS,
    "boundary.NAME.role": boundary.ROLES, "boundary.NAME.law": boundary.LAWS,
    "boundary.NAME.gap_coordinate": boundary.AXES, "boundary.NAME.side": boundary.BOX_FACES,
    "boundary.NAME.gap_interpolation": boundary.INTERPOLATIONS,
    "material.model": material.MODELS, "discretization.u_degree": DEGREES, "discretization.zeta_degree": DEGREES,
    "time.order": (1, 2), "memory.kernel": memory.KERNELS, "memory.rule": memory.RULES,
    "solver.linear": solver.LINEAR, "solver.method": solver.METHODS, "solver.damage_scheme": solver.DAMAGE_SCHEMES,
    "solver.contact_points": solver.CONTACT_POINTS,
    "output.fields": output.FIELD_NAMES, "output.precision": output.PRECISIONS, "accuracy.degrees": DEGREES,
    "accuracy.time": accuracy.TIME_MODES,
}

# BoundaryConfig fields that are not TOML keys, and where they come from.
DERIVED = {"name": "the table's NAME", "gap_table": "gap (given as rows)", "patch": "interval (on a box)"}


REQUIRED = "required"


class Key(NamedTuple):
    """One scene key as the reference shows it."""

    section: str
    key: str
    type: str
    default: object
    choices: tuple
    meaning: str


def _classes() -> Iterator[tuple[str, type]]:
    hints = typing.get_type_hints(Config)
    for s in SECTIONS:
        yield s.key, boundary.BoundaryConfig if s.key == "boundary" else hints[s.attr]


def fields() -> Iterator[tuple[str, dataclasses.Field]]:
    """(dotted key, dataclass field) of every section's dataclass (boundary: ``boundary.NAME.*``)."""
    for section, cls in _classes():
        prefix = "boundary.NAME" if section == "boundary" else section
        for f in dataclasses.fields(cls):
            if not (section == "boundary" and f.name in DERIVED):
                yield f"{prefix}.{f.name}", f


def keys() -> list[Key]:
    """Every scene key with its type, default, choices and meaning (KeyError: a key without a MEANING line)."""
    out = []
    for dotted, f in fields():
        section, key = dotted.rsplit(".", 1)
        default = f.default if f.default is not dataclasses.MISSING else (
            f.default_factory() if f.default_factory is not dataclasses.MISSING else REQUIRED)
        out.append(Key(section, key, str(f.type), default, CHOICES.get(dotted, ()), MEANING[dotted]))
    return out


def _show(v: object) -> str:
    if v is REQUIRED:
        return "required"
    if v is None or v == () or v == "":
        return "—"
    if isinstance(v, tuple):
        v = [list(x) if isinstance(x, tuple) else x for x in v]
    return "`" + repr(v).replace("'", '"').replace("True", "true").replace("False", "false") + "`"


def markdown() -> str:
    """The reference page (MyST Markdown): one table a section."""
    lines = ["# Scene keys", "", "<!-- generated by `python -m solver.config.reference` from solver/config/*.py; "
             "do not edit -->", "",
             "Every key a scene file (or `api.scene`/`Config.replace`) takes, with its type, its default (the paper's "
             "Example 1) and its allowed values. Generated from the configuration dataclasses; the validation "
             "itself is in `solver/config/` and says, for a wrong value, the key, the value and what is allowed.", ""]
    section = None
    for k in keys():
        if k.section != section:
            section = k.section
            title = "[boundary.NAME]" if section == "boundary.NAME" else f"[{section}]"
            lines += ["", f"## {title}", "", "| key | type | default | allowed | meaning |", "|---|---|---|---|---|"]
        allowed = ", ".join(f"`{c}`" for c in k.choices) or ""
        lines.append(f"| `{k.key}` | `{k.type.replace('|', chr(92) + '|')}` | {_show(k.default)} | {allowed} | {k.meaning} |")
    return "\n".join(lines) + "\n"


if __name__ == "__main__":
    print(markdown(), end="")
