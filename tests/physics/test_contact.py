"""The contact term: the compliance laws (linear, power, limited penetration), the Jacobian's active set
tracked between calls, and varying gaps against closed forms: the pressed block with the power and the
limited-penetration laws, a linear gap (a rigid rotation of a constant one, and the tilted foundation's
closed form), and the identities the issue asks for (power with m = 1 is the linear law, a constant gap
table is the constant gap)."""

import tomllib

import numpy as np
import pytest
from conftest import ROOT, contact_residuals, eval_point, solve, unit_mesh
from dolfinx import fem
from mpi4py import MPI
from scipy.optimize import brentq

from solver.config import apply_overrides, from_dict
from solver.physics.contact import normal_compliance
from solver.physics.contact_points import ContactPoints
from solver.run.model import build_model
from solver.run.stepper import Stepper

E, DELTA = 100.0, 1e-3
STATIC = {"memory": {"kernel": "none"}, "damage": {"enabled": False}, "time": {"T": 1.0, "k": 1.0}}


def test_normal_compliance_is_the_positive_part_over_mu(comm):
    mesh = unit_mesh(comm)
    for r, want in ((0.3, 0.3 / 1e-2), (-0.3, 0.0)):
        assert eval_point(normal_compliance(fem.Constant(mesh, r), 1e-2), mesh) == pytest.approx(want)


def test_jacobian_is_rebuilt_only_when_the_active_set_changes(comm):
    cfg = from_dict({"mesh": {"nx": 4, "ny": 4}, "memory": {"kernel": "none"}, "damage": {"enabled": False}})
    model = build_model(cfg, comm)
    term = model.mech.contact
    assert term.assemble_jacobian()  # the first call is new
    assert not term.assemble_jacobian()  # same u: same active set
    x = model.u.function_space.tabulate_dof_coordinates()
    u = model.u.x.array.reshape(-1, 2)
    u[:, 1] = -1e-3 * (x[:, 0] < 0.5)  # the left half of the bottom now penetrates
    model.u.x.scatter_forward()
    assert term.assemble_jacobian()
    u[:, 1] *= 2.0  # deeper, same points active: the Jacobian H(r)/mu is the same
    assert not term.assemble_jacobian()
    term.forget()
    assert term.assemble_jacobian()
    assert np.isfinite(term.C.norm())


def test_contact_term_is_the_ufl_residual(comm):
    cfg = from_dict({"mesh": {"nx": 4, "ny": 4}, "memory": {"kernel": "none"}, "damage": {"enabled": False}})
    model = build_model(cfg, comm)
    model.u.x.array[1::2] = -1e-3  # the whole body moved down by 1e-3
    F = model.mech.ops.b.duplicate()
    F.set(0.0)
    norm = model.mech.contact.add_residual(F)
    total = comm.allreduce(float(F.array[1::2].sum()), op=MPI.SUM)
    # sum of int p(u_nu - g) w_nu over the bottom for w = the y hat functions: p = 1e-3 / 1e-10 on a
    # length 1 with the outward normal -e_y, less the clamped corner's half cell (its row is zero)
    assert total == pytest.approx(-(1e-3 / 1e-10) * (1 - 1 / 8), rel=1e-10)
    assert norm == pytest.approx(F.norm())


def _pressed(bottom: dict, n: int = 4, nu: float = 0.0, **extra) -> dict:
    """Clamped top, the foundation below overlapping the body by DELTA (gap -DELTA unless given)."""
    return {**STATIC, "mesh": {"nx": n, "ny": n}, "material": {"E": E, "nu": nu},
            "boundary": {"top": {"role": "clamped"}, "bottom": {"role": "contact", "gap": -DELTA, **bottom}}, **extra}


def _max_error(model, exact) -> float:
    x = model.u.function_space.tabulate_dof_coordinates()
    u = model.u.x.array.reshape(-1, 2)
    return model.comm.allreduce(float(np.abs(u - exact(x)).max()), op=MPI.MAX)


def _uniaxial(a: float):
    """u = (0, a (1 - y)): the pressed block's closed form (nu = 0)."""
    return lambda x: np.column_stack([0 * x[:, 0], a * (1 - x[:, 1])])


@pytest.mark.parametrize("m", [1.5, 3.0])
def test_power_law_pressed_block(comm, m):
    """p(r) = c r^m: u_y = a (1 - y) with c (delta - a)^m = E a (nu = 0); Newton uses p'."""
    c = E * DELTA ** (1 - m)  # c delta^m = E delta: both sides matter
    a = brentq(lambda a: c * (DELTA - a) ** m - E * a, 0.0, DELTA, xtol=1e-300, rtol=4 * np.finfo(float).eps)
    model, rows = solve(from_dict(_pressed({"law": "power", "coefficient": c, "exponent": m})), comm)
    assert _max_error(model, _uniaxial(a)) < 1e-9 * a
    assert rows[-1]["contact_force"] == pytest.approx(E * a, rel=1e-9)
    assert rows[-1]["reaction_top_y"] == pytest.approx(-E * a, rel=1e-9)  # the clamp holds the block down
    assert 2 < rows[0]["newton_iterations"] <= 12  # a smooth law: several Newton steps, converged


@pytest.mark.parametrize("depth", [1e-4, 1e-3])
def test_limited_penetration_pressed_block(comm, depth):
    """p(r) = r_+/mu + (r - d)_+/mu_s: the soft layer alone (d = 1e-3: r = delta/2 < d) or used up
    (d = 1e-4): u_y = a (1 - y) with p(delta - a) = E a, piecewise linear in a."""
    mu, mu_s = 1e-2, 1e-6
    a = DELTA / (1 + E * mu)
    if DELTA - a > depth:
        a = (DELTA / mu + (DELTA - depth) / mu_s) / (E + 1 / mu + 1 / mu_s)
    law = {"law": "limited_penetration", "mu": mu, "depth": depth, "mu_stiff": mu_s}
    model, rows = solve(from_dict(_pressed(law)), comm)
    assert _max_error(model, _uniaxial(a)) < 1e-9 * a
    assert rows[-1]["contact_force"] == pytest.approx(E * a, rel=1e-9)
    assert rows[-1]["max_penetration"] == pytest.approx(DELTA - a, rel=1e-9)


def _example1(bottom: dict | None = None, overrides=()) -> dict:
    with open(ROOT / "configs/example1.toml", "rb") as fh:
        data = tomllib.load(fh)
    if bottom is not None:
        data["boundary"]["bottom"] = {"role": "contact", **bottom}
    return apply_overrides(data, ["mesh.nx=8", "mesh.ny=8", "time.k=0.1", *overrides])


def _levels(data: dict, comm) -> np.ndarray:
    """u at every level of a scene."""
    model = build_model(from_dict(data), comm)
    stepper, out = Stepper(model), []
    for n in range(model.cfg.time.steps + 1):
        stepper.step(n)
        out.append(model.u.x.array.copy())
    return np.array(out)


def test_power_law_with_exponent_one_is_the_linear_law(comm):
    """Example 1 with law = power, exponent = 1, coefficient = 1e10 equals the linear law (mu = 1e-10)."""
    linear = _levels(_example1(), comm)
    power = _levels(_example1({"law": "power", "exponent": 1.0, "coefficient": 1e10}), comm)
    err = comm.allreduce(float(np.abs(power - linear).max()), op=MPI.MAX)
    assert err <= 1e-10 * comm.allreduce(float(np.abs(linear).max()), op=MPI.MAX)


def test_constant_gap_table_is_the_constant_gap(comm):
    """A gap table with one value everywhere equals that gap (Example 1, gap 1e-3 with the body pressed in)."""
    number = _levels(_example1({"gap": 1e-3, "mu": 1e-10}), comm)
    table = _levels(_example1({"gap": [[0.0, 1e-3], [0.4, 1e-3], [1.0, 1e-3]], "mu": 1e-10}), comm)
    err = comm.allreduce(float(np.abs(table - number).max()), op=MPI.MAX)
    assert err <= 1e-12 * comm.allreduce(float(np.abs(number).max()), op=MPI.MAX)


def test_linear_gap_is_a_rotated_constant_gap(comm):
    """g(x) = g0 + s x on the bottom equals the constant gap g0 with the body turned by -s:
    u_A = u_B + (s y, -s x) at every level (memory and damage see no rigid motion), and the reactions agree.

    A's Dirichlet data are B's plus the rotation where it is constant along the part: u_x on the
    top (B: 0, A: s), u_y on the left (0, 0) and on the right (0, -s).
    """
    s, g0 = 1e-3, -1e-3
    common = {"mesh": {"nx": 4, "ny": 4}, "material": {"E": E, "nu": 0.3}, "time": {"T": 0.2, "k": 0.1},
              "body_force": {"f": [0.5, -2.0]}}
    B = {**common, "boundary": {
        "top": {"role": "displacement", "displacement": [0.0, "free"]},
        "left": {"role": "displacement", "displacement": ["free", 0.0]},
        "right": {"role": "displacement", "displacement": ["free", 0.0]},
        "bottom": {"role": "contact", "gap": g0, "mu": 1e-2}}}
    A = {**common, "boundary": {
        "top": {"role": "displacement", "displacement": [s, "free"]},
        "left": {"role": "displacement", "displacement": ["free", 0.0]},
        "right": {"role": "displacement", "displacement": ["free", -s]},
        "bottom": {"role": "contact", "gap": [[0.0, g0], [1.0, g0 + s]], "mu": 1e-2}}}
    (mA, rA), (mB, rB) = solve(from_dict(A), comm), solve(from_dict(B), comm)
    x = mA.u.function_space.tabulate_dof_coordinates()
    rotation = np.column_stack([s * x[:, 1], -s * x[:, 0]]).ravel()
    scale = comm.allreduce(float(np.abs(mB.u.x.array).max()), op=MPI.MAX)
    assert scale > 1e-4  # the foundation and the load do deform the body
    assert comm.allreduce(float(np.abs(mA.u.x.array - mB.u.x.array - rotation).max()), op=MPI.MAX) < 1e-12 * scale
    for ra, rb in zip(rA, rB):
        assert ra["contact_force"] == pytest.approx(rb["contact_force"], rel=1e-12)
        for key in ("reaction_top_x", "reaction_left_y", "reaction_right_y"):
            assert ra[key] == pytest.approx(rb[key], rel=1e-10, abs=1e-14)
    assert rA[-1]["zeta_min"] == pytest.approx(rB[-1]["zeta_min"], rel=1e-12)


def test_linear_gap_pressed_block_closed_form(comm):
    """Clamped top, overlap delta(x) = d0 + (d1 - d0) x, nu = 0. The exact solution is
    u = ((d1 - d0) (1 - y)^2 / 2, delta(x) (1 - y)) / (1 + E mu): sigma_yy = -E a(x), no shear, so the
    foundation pushes with p(x) = E a(x), a = delta / (1 + E mu). u is not P1, so: the total force
    (and the clamp's reaction) are exact, and the first moment int x p converges at second order."""
    mu, d0, d1 = 1e-2, 1e-3, 2e-3
    a0, a1 = d0 / (1 + E * mu), d1 / (1 + E * mu)
    force, moment = E * (a0 + a1) / 2, E * (a0 / 2 + (a1 - a0) / 3)
    errors = []
    for n in (4, 8, 16):
        model, rows = solve(from_dict(_pressed({"gap": [[0.0, -d0], [1.0, -d1]], "mu": mu}, n=n)), comm)
        assert rows[-1]["contact_force"] == pytest.approx(force, rel=1e-12)
        assert rows[-1]["reaction_top_y"] == pytest.approx(-force, rel=1e-12)
        pts = model.mech.diagnostics.points
        p = pts.pressure(pts.penetration(model.u.x.array))
        errors.append(abs(comm.allreduce(float((pts.W * p * pts.x[:, 0]).sum()), op=MPI.SUM) - moment))
    assert errors[1] < errors[0] / 3 and errors[2] < errors[1] / 3, errors


def test_contact_points_reproduce_the_ufl_term_for_every_law_and_a_varying_gap(comm):
    """N^T W p(N u - g) equals the assembled UFL contact residual for the power and limited-penetration
    laws on two parts with piecewise-linear gaps (the fixed-point methods and the penetration read the points)."""
    data = _example1()
    data["boundary"]["bottom"] = {"role": "contact", "interval": [0.0, 0.5], "law": "power", "coefficient": 2e4,
                                  "exponent": 1.5, "gap": [[0.0, 0.01], [0.25, -0.02], [0.5, 0.0]]}
    data["boundary"]["bottom2"] = {"role": "contact", "side": "bottom", "interval": [0.5, 1.0], "law": "limited_penetration",
                                   "mu": 1e-2, "depth": 0.005, "mu_stiff": 1e-3, "gap": [[0.6, -0.01], [0.9, 0.0]]}
    cfg = from_dict(data)
    m = build_model(cfg, comm)
    m.mech.solve(0.0)
    pts = ContactPoints(m.geo, m.u.function_space, cfg.contact, cfg.solver.contact_quadrature_degree)
    r = pts.penetration(m.u.x.array)
    (power, _), (limited, n) = pts.laws.runs  # bottom's points, then bottom2's
    assert power == cfg.contact[0].contact_law and limited == cfg.contact[1].contact_law
    deep = r[r.size - n:] > limited.depth  # the stiff part of the second law acts
    assert comm.allreduce(int(deep.sum()), op=MPI.SUM) > 0
    F, G = contact_residuals(m, pts.forces(pts.pressure(r)))
    assert (F - G).norm() <= 1e-12 * F.norm()
    total = comm.allreduce(float((pts.W * pts.pressure(r)).sum()), op=MPI.SUM)
    assert total == pytest.approx(m.mech.diagnostics.contact_force(), rel=1e-12)


@pytest.mark.parametrize("method", ["fixed_point", "penalty_duality"])
def test_limited_penetration_with_every_method(comm, method):
    """Penalty-duality (the three-piece resolvent) and the fixed point (on a foundation soft enough
    for it to contract) solve the limited-penetration law to Newton's answer."""
    mu = "1.0" if method == "fixed_point" else "1e-2"
    law = {"law": "limited_penetration", "mu": float(mu), "depth": 0.02, "mu_stiff": float(mu) / 4, "gap": 0.0}
    out = {}
    for name in ("newton", method):
        model, rows = solve(from_dict(_example1(law, [f"solver.method='{name}'", "solver.max_it=300"])), comm)
        out[name] = model.u.x.array.copy(), rows
    (un, rn), (uo, ro) = out["newton"], out[method]
    assert comm.allreduce(float(rn[0]["max_penetration"]), op=MPI.MAX) > 0.02  # the stiff part acts
    assert max(r["newton_iterations"] for r in ro) > 1  # iterated on the contact forces
    scale = comm.allreduce(float(np.abs(un).max()), op=MPI.MAX)
    assert comm.allreduce(float(np.abs(un - uo).max()), op=MPI.MAX) < 1e-8 * scale
