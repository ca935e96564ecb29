"""A law's number in its UFL form as a ``fem.Constant``: the compiled form's signature then does not depend on the
value, so a sweep of a compliance, a material constant or a memory truncation compiles its forms once (FFCx
compiles a literal number into the C code, a new module for every value)."""

from __future__ import annotations

import numpy as np
import ufl
from ufl.domain import extract_unique_domain


def constant(like: ufl.core.expr.Expr, value: float) -> ufl.core.expr.Expr:
    """``value`` as a ``fem.Constant`` on the mesh of the expression ``like``; the plain number where ``like`` is on
    no dolfinx mesh (a UFL literal, as in a check of the law by itself with UFL's evaluator, which knows no Constant
    it is not given)."""
    try:
        domain = extract_unique_domain(like)
    except ValueError:  # several meshes: cannot be, a law's argument is on one
        domain = None
    if domain is None or domain.ufl_cargo() is None:  # a bare UFL mesh: no dolfinx mesh (cargo) behind it
        return ufl.as_ufl(float(value))
    from dolfinx import fem  # here, not at the top: the laws' numpy forms need no dolfinx

    return fem.Constant(domain, np.float64(value))
