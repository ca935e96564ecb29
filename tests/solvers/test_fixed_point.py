"""The fixed-point contact methods: Newton's answers where they work,
loud named failures where they do not (never a silently wrong answer)."""


import numpy as np
import pytest
from conftest import ROOT, solve

from solver.config import load
from solver.errors import DisplacementSolveError

EX1 = ROOT / "configs/example1.toml"
SMALL = ["mesh.nx=8", "mesh.ny=8", "time.k=0.1"]


@pytest.mark.parametrize("mu", ["1e-2", "1e-10"])
def test_penalty_duality_equals_newton(comm, mu):
    out = {}
    for method in ("newton", "penalty_duality"):
        cfg = load(EX1, [*SMALL, f"boundary.bottom.mu={mu}", f"solver.method='{method}'", "solver.max_it=200"])
        model, rows = solve(cfg, comm)
        out[method] = (model.u.x.array.copy(), rows)
    (un, rn), (up, rp) = out["newton"], out["penalty_duality"]
    assert np.allclose(un, up, rtol=0, atol=1e-9 * np.abs(un).max())
    assert rp[-1]["strain_norm"] == pytest.approx(rn[-1]["strain_norm"], rel=1e-9)
    assert np.mean([r["newton_iterations"] for r in rp[1:]]) > 5  # a fixed point: many cheap iterations
    assert sum(r["factorizations"] for r in rp) == 1  # its matrix is factored once, at the first solve


def test_fixed_point_converges_on_a_soft_foundation_only(comm):
    soft = load(EX1, [*SMALL, "boundary.bottom.mu=1.0", "solver.method='fixed_point'", "solver.max_it=200"])
    ref = load(EX1, [*SMALL, "boundary.bottom.mu=1.0"])
    rf, rn = solve(soft, comm)[1], solve(ref, comm)[1]
    assert rf[-1]["strain_norm"] == pytest.approx(rn[-1]["strain_norm"], rel=1e-9)
    stiff = load(EX1, [*SMALL, "solver.method='fixed_point'", "solver.max_it=200"])
    with pytest.raises(DisplacementSolveError) as err:
        solve(stiff, comm)
    assert (err.value.step, err.value.method, err.value.reason) == (0, "fixed_point", "DIVERGED_RESIDUAL_GROWTH")
    assert err.value.kind == "diverged"


def test_penalty_duality_fails_loudly_when_contact_releases(comm):
    """On the hard scene part of the contact lifts off: with omega ~ 1/mu the multiplier update
    contracts by (omega - E)/(omega + E) ~ 1 - 4e-8 there, and the method must say so."""
    cfg = load(ROOT / "configs/hard.toml", ["mesh.nx=8", "mesh.ny=8", "time.k=0.1", "solver.method='penalty_duality'",
                                            "solver.max_it=200"])
    with pytest.raises(DisplacementSolveError) as err:
        solve(cfg, comm)
    assert (err.value.step, err.value.method, err.value.reason) == (3, "penalty_duality", "DIVERGED_STAGNATION")
    assert err.value.t == pytest.approx(0.3) and err.value.kind == "stagnated"
