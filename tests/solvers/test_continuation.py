"""The compliance path of a first contact (solver/solvers/continuation.py): Hertz line contact, a half block pushed
0.005 onto g = x²/2 with mu = 1e-8, reaches the stiff law's solution in at most 10 Newton iterations where Newton
alone takes 13 (P1, n = 100; auto 21), and to the same solution."""

import numpy as np
import pytest
from conftest import ROOT

import solver.solvers.continuation as continuation
from solver.config import from_dict, load
from solver.run.model import build_model
from solver.run.stepper import Stepper
from solver.solvers.continuation import (
    DECIDE_STEPS,
    STIFF,
    ComplianceContinuation,
    ZoneShrinks,
    contact_stiffness_ratio,
)


def hertz_line(n: int, mu: float = 1e-8, method: str = "auto", degree: int = 1) -> dict:
    """The half block (0, 1)², symmetric about x = 0, its top pushed down 0.005 onto the parabola g = x²/2."""
    s = np.linspace(0.0, 1.0, 5)
    return {"memory": {"kernel": "none"}, "damage": {"enabled": False}, "time": {"T": 1.0, "k": 1.0},
            "mesh": {"nx": n, "ny": n}, "material": {"E": 1.0, "nu": 0.3}, "solver": {"method": method},
            "discretization": {"u_degree": degree},
            "boundary": {"left": {"role": "displacement", "displacement": [0.0, "free"]},
                         "top": {"role": "displacement", "displacement": ["free", -0.005]},
                         "bottom": {"role": "contact", "mu": mu, "gap": [[v, v * v / 2] for v in s],
                                    "gap_coordinate": "x", "gap_interpolation": "cubic"}}}


def first_level(comm, n: int, method: str = "auto", mu: float = 1e-8, degree: int = 1) -> dict:
    return Stepper(build_model(from_dict(hertz_line(n, mu, method, degree)), comm)).step(0)


@pytest.mark.parametrize("method", ["auto", "newton"])
def test_first_contact_in_few_iterations(comm, method, monkeypatch):
    row = first_level(comm, 100, method)
    monkeypatch.setattr(ComplianceContinuation, "applies", lambda self: False)
    plain = first_level(comm, 100, method)
    print(method, "iterations with the path", row["newton_iterations"], "without", plain["newton_iterations"])
    assert row["newton_iterations"] <= 10 < plain["newton_iterations"]
    for key in ("contact_force", "contact_length", "strain_norm"):
        assert row[key] == pytest.approx(plain[key], rel=1e-9), key


def test_path_only_for_a_stiff_contact(comm):
    stiff = build_model(from_dict(hertz_line(16)), comm).mech.problem
    soft = build_model(from_dict(hertz_line(16, mu=1.0)), comm).mech.problem
    assert contact_stiffness_ratio(stiff) > STIFF > contact_stiffness_ratio(soft) > 0.0
    path = ComplianceContinuation(stiff)
    assert path.scales == tuple(sorted(path.scales)) and 0.0 < path.scales[0] and path.scales[-1] < 1.0
    assert path.applies()  # u = 0 touches nothing: a first contact
    assert ComplianceContinuation(soft).scales == ()
    limited = hertz_line(16)
    limited["boundary"]["bottom"].update(law="limited_penetration", mu=1e-6, depth=1e-7, mu_stiff=1e-10)
    assert ComplianceContinuation(build_model(from_dict(limited), comm).mech.problem).scales == ()  # linear law only


def test_newton_condensed_first_contact_takes_the_path(comm, monkeypatch):
    """newton_condensed's iteration on the contact dofs (reduced.PointReduced) takes the same path on a level that
    starts with no point in contact: fewer iterations than from the plain start, the same solution."""
    from solver.solvers.reduced import PointReduced

    row = first_level(comm, 50, "newton_condensed")
    monkeypatch.setattr(PointReduced, "_path_scales", lambda self: ())
    plain = first_level(comm, 50, "newton_condensed")
    print("newton_condensed iterations with the path", row["newton_iterations"], "without", plain["newton_iterations"])
    assert row["newton_iterations"] < plain["newton_iterations"]
    for key in ("contact_force", "contact_length", "strain_norm"):
        assert row[key] == pytest.approx(plain[key], rel=1e-9), key


@pytest.mark.parametrize(("n", "degree", "most"), [(50, 1, 8), (32, 2, 9)])
def test_a_shrinking_zone_takes_the_path_after_two_iterations(comm, n, degree, most, monkeypatch):
    """Hertz line contact: C has fewer rows at Newton's second iterate than at its first (the zone of the solve
    without contact closing), so the path starts after DECIDE_STEPS plain iterations instead of FIRST_STEPS: one
    iteration fewer (P1 n = 50: 9 -> 8, P2 n = 32: 10 -> 9), the same solution."""
    row = first_level(comm, n, degree=degree)
    monkeypatch.setattr(ZoneShrinks, "__call__", lambda self, it: False)
    late = first_level(comm, n, degree=degree)
    print("iterations, path after", DECIDE_STEPS, row["newton_iterations"], "after 3", late["newton_iterations"])
    assert row["newton_iterations"] <= most < late["newton_iterations"]
    for key in ("contact_force", "contact_length", "strain_norm"):
        assert row[key] == pytest.approx(late[key], rel=1e-9), key


def test_zone_shrinks_compares_the_first_two_iterates(monkeypatch):
    """True at iteration DECIDE_STEPS only, where C's rows fell from the first iterate; the start (iteration 0, no
    contact) and later iterates are not counted."""
    for rows, stops in (([21, 19], True), ([17, 17], False), ([8, 9], False)):
        counts = iter(rows)
        monkeypatch.setattr(continuation, "contact_rows", lambda problem, counts=counts: next(counts))
        watch = ZoneShrinks(None)
        assert [watch(it) for it in range(DECIDE_STEPS + 2)] == [False, False, stops, False]
        assert watch.rows == rows


def test_a_kept_zone_keeps_plain_newton(comm, monkeypatch):
    """configs/example1.toml (8 x 8): the first level's zone is the same at Newton's first two iterates (8 rows
    of C), and plain Newton settles it at the third, as before the early path."""
    seen = []
    call = ZoneShrinks.__call__

    def spy(self, it):
        out = call(self, it)
        seen.append((it, out))
        return out

    monkeypatch.setattr(ZoneShrinks, "__call__", spy)
    model = build_model(load(ROOT / "configs" / "example1.toml", ["mesh.nx=8", "mesh.ny=8", "time.T=0.02"]), comm)
    row = Stepper(model).step(0)
    assert (DECIDE_STEPS, False) in seen
    assert row["newton_iterations"] == 3
