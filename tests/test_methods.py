"""The displacement methods, the damage and memory variants: same answers where they work,
loud named failures where they do not (never a silently wrong answer)."""

import math

import numpy as np
import pytest
from conftest import ROOT, solve
from dolfinx import fem
from mpi4py import MPI
from petsc4py import PETSc

from solver.config import DamageConfig, from_dict, load
from solver.contact_points import ContactPoints
from solver.damage import Damage
from solver.errors import ConfigError, DamageSolveError, DisplacementSolveError
from solver.stepper import build_model

EX1 = ROOT / "configs/example1.toml"
SMALL = ["mesh.nx=8", "mesh.ny=8", "time.k=0.1"]


def test_contact_points_reproduce_the_ufl_contact_term(comm):
    """N^T W p(N u - g) equals the assembled contact residual, and N u - g is the penetration."""
    from dolfinx.fem import petsc as fpetsc

    cfg = load(ROOT / "configs/hard.toml", ["mesh.nx=8", "mesh.ny=8"])
    m = build_model(cfg, comm)
    m.mech.solve(0.0)
    pts = ContactPoints(m.geo, m.u.function_space, cfg.contact, cfg.solver.contact_quadrature_degree)
    F = m.mech.ops.b.duplicate()
    with F.localForm() as f:
        f.set(0.0)
    fpetsc.assemble_vector(F, m.mech.contact.residual_form)
    F.ghostUpdate(addv=PETSc.InsertMode.ADD, mode=PETSc.ScatterMode.REVERSE)
    G = F.duplicate()
    with G.localForm() as g:
        g.array[:] = pts.forces(np.maximum(pts.penetration(m.u.x.array), 0) / cfg.contact[0].mu)
    G.ghostUpdate(addv=PETSc.InsertMode.ADD, mode=PETSc.ScatterMode.REVERSE)
    # both evaluate p = (u.n - g) / mu: the difference of O(|u|) numbers at quadrature points, so
    # round-off of eps |u| is amplified by 1/mu = 1e10 (2e-9 seen with OpenBLAS, 1e-16 with the
    # reference BLAS); a wrong normal, point or weight would differ by O(||F||)
    eps_bound = 10 * np.finfo(float).eps * comm.allreduce(np.abs(m.u.x.array).max(), op=MPI.MAX) / cfg.contact[0].mu
    assert (F - G).norm() <= 1e-14 * F.norm() + eps_bound * m.geo.measure("bottom")
    # total force: sum of W p over the points = the contact-force functional
    r = pts.penetration(m.u.x.array)
    total = comm.allreduce(float((pts.W * np.maximum(r, 0) / cfg.contact[0].mu).sum()), op=MPI.SUM)
    assert total == pytest.approx(m.mech.diagnostics.contact_force(), rel=1e-12)


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
    assert err.value.status == "diverged"


def test_penalty_duality_fails_loudly_when_contact_releases(comm):
    """On the hard scene part of the contact lifts off: with omega ~ 1/mu the multiplier update
    contracts by (omega - E)/(omega + E) ~ 1 - 4e-8 there, and the method must say so."""
    cfg = load(ROOT / "configs/hard.toml", ["mesh.nx=8", "mesh.ny=8", "time.k=0.1", "solver.method='penalty_duality'",
                                            "solver.max_it=200"])
    with pytest.raises(DisplacementSolveError) as err:
        solve(cfg, comm)
    assert (err.value.step, err.value.method, err.value.reason) == (3, "penalty_duality", "DIVERGED_STAGNATION")
    assert err.value.t == pytest.approx(0.3) and err.value.status == "stagnated"


def test_semi_implicit_damage_is_linearised_implicit_euler(comm):
    """With eps = 0 and a uniform zeta the semi-implicit step is z + k phi / (1 - k phi_z), exactly."""
    from dolfinx import mesh

    m = mesh.create_unit_square(comm, 4, 4)
    u = fem.Function(fem.VectorFunctionSpace(m, ("CG", 1)))
    cfg = DamageConfig(lambda1=0.5, zeta0=0.9, clip=False)
    k = 0.1
    d = Damage(fem.FunctionSpace(m, ("CG", 1)), u, cfg, k, 2, scheme="semi_implicit")
    z = 0.9
    for _ in range(4):
        d.step()
        phi, phi_z = -cfg.lambda1 * (1 - z) / z, cfg.lambda1 / z**2
        z = z + k * phi / (1 - k * phi_z)
        assert np.allclose(d.zeta.x.array, z, rtol=0, atol=1e-13)


def _patch(rule: str, k: float):
    return from_dict({
        "mesh": {"nx": 4, "ny": 3, "corners": [[0, 0], [2, 1]]},
        "boundary": {"left": {"role": "clamped"}, "right": {"role": "traction", "traction": [10.0, 0.0]}},
        "material": {"E": 100.0, "nu": 0.0},
        "memory": {"kernel": "exponential", "weights": [-1.0], "times": [1.0], "L": 6.0, "rule": rule},
        "damage": {"enabled": False, "zeta0": 0.8},
        "time": {"T": 0.5, "k": k},
    })


def test_trapezoidal_memory_patch_closed_form(comm):
    """Uniform stress t = E eps_n + P_n + (k/2) g(0) zeta0 min(L, E eps_n), P by the trapezoid
    recursion (H_0 at weight k/2): the implicit current-level term, truncation acting."""
    E, t, k, z0, L, c = 100.0, 10.0, 0.1, 0.8, 6.0, -1.0
    model, rows = solve(_patch("trapezoid", k), comm)
    d = math.exp(-k)
    P, eps = 0.0, []
    for n in range(len(rows)):
        if n == 1:
            P = d * 0.5 * k * c * z0 * min(L, E * eps[0])
        elif n > 1:
            P = d * (P + k * c * z0 * min(L, E * eps[-1]))
        # E e + (k/2) c z0 min(L, E e) = t - P, piecewise linear in e
        a = 0.5 * k * c * z0 if n > 0 else 0.0
        e = (t - P) / (E + a * E)
        if E * e > L:
            e = (t - P - a * L) / E
        eps.append(e)
    x = model.u.function_space.tabulate_dof_coordinates()
    ux = model.u.x.array.reshape(-1, 2)[:, 0]
    sel = np.isclose(x[:, 0], 2.0)
    got = comm.allreduce(float(ux[sel].max() / 2.0) if sel.any() else -np.inf, op=MPI.MAX)
    assert got == pytest.approx(eps[-1], rel=1e-10)


def test_trapezoid_is_more_accurate_in_time(comm):
    """Final strain of the patch: the trapezoid at k = 0.1 is closer to a fine left-rule run than the left rule."""
    def final(rule, k):
        return solve(_patch(rule, k), comm)[1][-1]["strain_norm"]
    fine = final("left", 0.005)
    assert abs(final("trapezoid", 0.1) - fine) < 0.3 * abs(final("left", 0.1) - fine)


def test_trapezoid_needs_newton():
    with pytest.raises(ConfigError) as err:
        from_dict({"memory": {"rule": "trapezoid"}, "solver": {"method": "penalty_duality"}})
    assert err.value.key == "memory.rule"


def test_semi_implicit_damage_refuses_an_unstable_step(comm):
    """On the hard scene zeta nears zeta* and k lambda1 / zeta^2 passes 1 at k = 0.1: a named failure,
    where clipping would otherwise hide a zeta of about -50."""
    cfg = load(ROOT / "configs/hard.toml", ["mesh.nx=8", "mesh.ny=8", "time.k=0.1",
                                            "solver.damage_scheme='semi_implicit'"])
    with pytest.raises(DamageSolveError) as err:
        solve(cfg, comm)
    assert err.value.reason == "SEMI_IMPLICIT_UNSTABLE" and err.value.step >= 1
