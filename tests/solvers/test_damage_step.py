"""The damage step's invariants (solver/solvers/damage_step.py); the source's law is tests/laws/test_damage.py."""


import numpy as np
import pytest
from conftest import ROOT, solve, unit_mesh
from dolfinx import fem
from mpi4py import MPI

from solver.config import DamageConfig, load
from solver.errors import DamageSolveError
from solver.run.model import build_model
from solver.solvers.damage_step import (
    CNAB2Damage,
    ExplicitDamage,
    SemiImplicitDamage,
    make_damage,
)


def _damage(comm, cfg, k=0.1, n=6):
    m = unit_mesh(comm, n)
    u = fem.Function(fem.VectorFunctionSpace(m, ("CG", 1)))
    return ExplicitDamage(fem.FunctionSpace(m, ("CG", 1)), u, cfg, k, 2), u


def _integral(d):
    return d.V.mesh.comm.allreduce(fem.assemble_scalar(fem.form(d.zeta * __import__("ufl").dx)), op=MPI.SUM)


def test_zero_source_keeps_uniform_and_conserves(comm):
    cfg = DamageConfig(lambda1=0.0, lambda2=0.0, lambda3=0.0, zeta0=0.7)
    d, _ = _damage(comm, cfg)
    before = _integral(d)
    for _ in range(5):
        d.step()
    assert np.allclose(d.zeta.x.array, 0.7, rtol=0, atol=1e-13)
    assert _integral(d) == pytest.approx(before, rel=1e-13)


def test_nonuniform_zero_source_conserves_and_smooths(comm):
    cfg = DamageConfig(lambda1=0.0, lambda2=0.0, lambda3=0.0, kappa=0.1, clip=False)
    d, _ = _damage(comm, cfg)
    d.zeta.interpolate(lambda x: 0.5 + 0.4 * np.cos(np.pi * x[0]))
    before = _integral(d)
    spread0 = comm.allreduce(np.ptp(d.zeta.x.array), op=MPI.MAX)
    for _ in range(5):
        d.step()
    assert _integral(d) == pytest.approx(before, rel=1e-12)
    assert comm.allreduce(np.ptp(d.zeta.x.array), op=MPI.MAX) < spread0


def test_uniform_source_is_forward_euler(comm):
    """With eps = 0 the source depends on zeta only: a uniform zeta follows forward Euler exactly."""
    cfg = DamageConfig(lambda1=0.5, zeta0=0.9, clip=False)
    k = 0.1
    d, _ = _damage(comm, cfg, k=k)
    z = 0.9
    for _ in range(4):
        info = d.step()
        e = max(z, cfg.zeta_star)
        z = z + k * (-cfg.lambda1 * (1 - e) / e)
        assert np.allclose(d.zeta.x.array, z, atol=1e-13)
        assert info.clipped == 0


def test_clipping_counts_and_bounds(comm):
    cfg = DamageConfig(lambda1=5.0, zeta0=0.05, clip=True)
    d, _ = _damage(comm, cfg, k=0.1)
    info = d.step()  # 0.05 - 0.1 * 5 * 0.95 / 0.05 < zeta*: every node clipped
    nglobal = d.V.dofmap.index_map.size_global
    assert info.clipped == nglobal
    assert info.raw_min < cfg.zeta_star
    assert np.all(d.zeta.x.array >= cfg.zeta_star)


def test_semi_implicit_damage_is_linearised_implicit_euler(comm):
    """With eps = 0 and a uniform zeta the semi-implicit step is z + k phi / (1 - k phi_z), exactly."""
    from dolfinx import mesh

    m = mesh.create_unit_square(comm, 4, 4)
    u = fem.Function(fem.VectorFunctionSpace(m, ("CG", 1)))
    cfg = DamageConfig(lambda1=0.5, zeta0=0.9, clip=False)
    k = 0.1
    d = SemiImplicitDamage(fem.FunctionSpace(m, ("CG", 1)), u, cfg, k, 2)
    z = 0.9
    for _ in range(4):
        d.step()
        phi, phi_z = -cfg.lambda1 * (1 - z) / z, cfg.lambda1 / z**2
        z = z + k * phi / (1 - k * phi_z)
        assert np.allclose(d.zeta.x.array, z, rtol=0, atol=1e-13)


def test_semi_implicit_damage_refuses_an_unstable_step(comm):
    """On the hard scene zeta nears zeta* and k lambda1 / zeta^2 passes 1 at k = 0.1: a named failure,
    where clipping would otherwise hide a zeta of about -50."""
    cfg = load(ROOT / "configs/hard.toml", ["mesh.nx=8", "mesh.ny=8", "time.k=0.1",
                                            "solver.damage_scheme='semi_implicit'"])
    with pytest.raises(DamageSolveError) as err:
        solve(cfg, comm)
    assert err.value.reason == "SEMI_IMPLICIT_UNSTABLE" and err.value.step >= 1


@pytest.mark.parametrize("scheme,cls", [("explicit", ExplicitDamage), ("semi_implicit", SemiImplicitDamage),
                                        ("cnab2", CNAB2Damage)])
def test_make_damage_picks_the_class_of_the_scheme(comm, scheme, cls):
    m = unit_mesh(comm)
    u = fem.Function(fem.VectorFunctionSpace(m, ("CG", 1)))
    d = make_damage(scheme, fem.FunctionSpace(m, ("CG", 1)), u, DamageConfig(), 0.1, 2)
    assert type(d) is cls
    # only the two-step scheme carries checkpoint state and a first-step corrector
    assert bool(d.state()) == bool(d.scalars()) == (cls is CNAB2Damage)
    assert hasattr(d, "correct_first_step") == (cls is CNAB2Damage)
    with pytest.raises(ValueError, match="unknown damage scheme"):
        make_damage("implicit", d.V, u, DamageConfig(), 0.1, 2)


@pytest.mark.parametrize("sets,cls", [([], ExplicitDamage), (["solver.damage_scheme='semi_implicit'"], SemiImplicitDamage),
                                      (["time.order=2"], CNAB2Damage)])
def test_the_model_takes_the_damage_of_its_time_scheme(comm, sets, cls):
    cfg = load(ROOT / "configs/example1.toml", ["mesh.nx=4", "mesh.ny=4", *sets])
    assert type(build_model(cfg, comm).damage) is cls


def test_cnab2_corrects_only_its_first_step(comm):
    """Heun's corrector needs zeta_0, kept by the first step alone; it starts from zeta_0 again, so the corrected
    zeta_1 of a zero source is the predicted one."""
    cfg = DamageConfig(lambda1=0.0, lambda2=0.0, lambda3=0.0, kappa=0.1, clip=False)
    m = unit_mesh(comm, 6)
    u = fem.Function(fem.VectorFunctionSpace(m, ("CG", 1)))
    d = CNAB2Damage(fem.FunctionSpace(m, ("CG", 1)), u, cfg, 0.1, 2)
    d.zeta.interpolate(lambda x: 0.5 + 0.4 * np.cos(np.pi * x[0]))
    with pytest.raises(RuntimeError, match="first step"):
        d.correct_first_step()
    d.step()
    predicted = d.zeta.x.array.copy()
    d.correct_first_step()
    assert np.allclose(d.zeta.x.array, predicted, rtol=0, atol=1e-14)
    assert d.scalars() == {"have_prev": 1.0}
    d.step()
    with pytest.raises(RuntimeError, match="first step"):
        d.correct_first_step()
