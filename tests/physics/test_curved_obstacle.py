"""A curved obstacle with a known pressure (docs/contact.md §3): the block (0,1)² with ν = 0, clamped on top,
pressed by obstacles below and on both sides whose gaps are the quadratics of the exact solution

    u = (f'(x) (1 − y)²/2, (1 − y) f(x)),   f(x) = a + c (x − 1/2)²  (a = 1.25 |c|, c < 0),
    σ = E diag(c (1 − y)², −f(x)),   p = E f(x) on the bottom,  −E c (1 − y)² on the sides,

which satisfies div σ = 0 and σ_xy = 0 (frictionless): the pressure is parabolic, a Hertz-like dome. The
gaps are g = u_ν − μ p (bottom: −(1 + μE) f(x)), given as 5-row tables with the cubic spline (exact for a
quadratic). The reported pressure (the lumped-mass recovery of the law's pressure at the quadrature points,
contact_traces.py) converges to p under refinement: observed O(h²) in the maximum over the bottom's vertices in
1/4 <= x <= 3/4 (n = 8, 16, 32: errors 8.3e-3, 2.3e-3, 5.4e-4, rates 1.9, 2.1); over the whole bottom the corner
vertex, where the bottom's and a side's contact meet, reads the mean over half a hat, an O(h p') error
(9.8e-3, 8.1e-3, 4.6e-3, rates 0.3, 0.8; λ_h, the L² projection reported before, had 2.3e-2, 1.3e-2, 7.0e-3)
(docs/guide/contact.md states the figures)."""

import numpy as np

from solver.config import from_dict
from solver.run.model import build_model
from solver.run.stepper import Stepper

E, MU, C = 100.0, 1e-3, -1e-3
A = 1.25 * abs(C)


def f(x):
    return A + C * (x - 0.5) ** 2


def exact_pressure_bottom(x):
    return E * f(x)


def scene(n: int) -> dict:
    s = np.linspace(0.0, 1.0, 5)
    bottom = [[v, -(1 + MU * E) * f(v)] for v in s]
    side = [[v, C * (1 - v) ** 2 / 2 + MU * E * C * (1 - v) ** 2] for v in s]
    law = {"role": "contact", "mu": MU, "gap_interpolation": "cubic"}
    return {"memory": {"kernel": "none"}, "damage": {"enabled": False}, "time": {"T": 1.0, "k": 1.0},
            "mesh": {"nx": n, "ny": n}, "material": {"E": E, "nu": 0.0},
            "boundary": {"top": {"role": "clamped"}, "bottom": {**law, "gap": bottom},
                         "left": {**law, "gap": side}, "right": {**law, "gap": side}}}


def pressure_error(n: int, comm) -> tuple[float, float]:
    """max over the bottom's vertices of |p_h − E f| / max p in 1/4 <= x <= 3/4 and everywhere, p_h from the
    contact traces (the written field)."""
    model = build_model(from_dict(scene(n)), comm)
    Stepper(model).step(0)
    profile = model.mech.diagnostics.traces.profile()
    err = None
    if comm.rank == 0:
        rows = dict(profile)["bottom"]
        e = np.abs(rows[:, 7] - exact_pressure_bottom(rows[:, 1])) / (E * A)
        err = (float(e[np.abs(rows[:, 1] - 0.5) <= 0.25].max()), float(e.max()))
    return comm.bcast(err, root=0)


def test_curved_obstacle_pressure_converges(comm):
    errors = np.array([pressure_error(n, comm) for n in (8, 16, 32)])
    rates = np.log2(errors[:-1] / errors[1:])
    print("errors (interior, all)", errors.tolist(), "rates", rates.tolist())
    assert errors[-1, 0] < 1e-3 and errors[-1, 1] < 1e-2
    assert np.all(rates[:, 0] > 1.8)
    assert rates[-1, 1] > 0.7
