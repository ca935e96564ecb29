"""The history buffer: recursions against the direct sum M_n = k sum_m g((n-m)k) H_m."""

import math

import numpy as np
import pytest
import ufl
from conftest import solve, unit_mesh
from dolfinx import fem
from dolfinx.fem import petsc as fpetsc
from mpi4py import MPI
from petsc4py import PETSc

from solver.config import MemoryConfig, from_dict
from solver.errors import ConfigError
from solver.laws.memory import MemoryIntegrand
from solver.physics.material import elasticity, lame, strain
from solver.physics.memory import PronyHistory, make_history, memory_source, trapezoid_term
from solver.physics.memory_source import MemorySource
from solver.physics.quadrature import QuadratureRule


def A(eps):
    return elasticity(eps, 100.0, 0.3, "plane_stress")


def law(L):
    return MemoryIntegrand(L, *lame(100.0, 0.3, "plane_stress"))


def _setup(comm, degree=1):
    m = unit_mesh(comm, 4)
    u = fem.Function(fem.VectorFunctionSpace(m, ("CG", 1)))
    zeta = fem.Function(fem.FunctionSpace(m, ("CG", 1)))
    rule = QuadratureRule(m, degree)
    return m, u, zeta, rule


def _drive(u, zeta, n):
    """A different (u, zeta) at each level n, large enough for the truncation to act sometimes."""
    u.interpolate(lambda x: np.vstack([(1 + n) * x[0] ** 2 + np.sin(n * x[1]), 5 * x[0] * x[1] * (n % 3)]))
    zeta.interpolate(lambda x: 0.2 + 0.7 * np.abs(np.cos(n + x[0] + x[1])))


def _direct(hs, g, k, n):
    return k * sum(g((n - m) * k) * hs[m] for m in range(n))


KERNELS = {
    "constant": (MemoryConfig(kernel="constant", weights=(1.3,), L=150.0), lambda s: 1.3),
    "exponential": (MemoryConfig(kernel="exponential", weights=(-1.0,), times=(1.0,), L=150.0), lambda s: -math.exp(-s)),
    "prony3": (
        MemoryConfig(kernel="exponential", weights=(2.0, -0.5, 0.25), times=(0.1, 1.0, 50.0), L=150.0),
        lambda s: 2 * math.exp(-s / 0.1) - 0.5 * math.exp(-s) + 0.25 * math.exp(-s / 50),
    ),
}


@pytest.mark.parametrize("name", list(KERNELS))
@pytest.mark.parametrize("degree", [1, 2])
def test_recursion_matches_direct_sum(comm, name, degree):
    cfg, g = KERNELS[name]
    m, u, zeta, rule = _setup(comm, degree)
    k, steps = 0.05, 12
    hist = make_history(cfg, "left", rule, MemorySource(rule, u, zeta, law(cfg.L)), k, steps)
    assert isinstance(hist, PronyHistory)
    probe = rule.evaluator(memory_source(u, zeta, A, cfg.L), hist.M.function_space)  # the definition, in UFL
    hs = []
    for n in range(steps):
        _drive(u, zeta, n)
        hs.append(probe().copy())
        hist.commit(n)
        want = _direct(hs, g, k, n + 1)
        assert np.allclose(hist.M.x.array, want, rtol=1e-12, atol=1e-12 * np.abs(want).max())
    # the truncation acted on the last level: some |A eps| exceeds L
    raw = rule.evaluator(A(strain(u)), hist.M.function_space)()
    assert comm.allreduce(np.abs(raw).max(), op=MPI.MAX) > cfg.L


@pytest.mark.parametrize("sum_rule", ["left", "trapezoid_extrapolated"])
def test_tabulated_kernel_matches_prony(comm, sum_rule):
    """A table of a two-term Prony kernel, sampled at the step times (rows at k/2), runs as the recursion with the two
    terms found back (no past kept): M equals the Prony kernel's to 1e-12, with either rule."""
    m, u, zeta, rule = _setup(comm)
    k, steps = 0.1, 8
    s = 0.5 * k * np.arange(2 * steps + 3)
    table = tuple((float(si), float(-np.exp(-si) - 0.5 * np.exp(-si / 0.3))) for si in s)
    src = MemorySource(rule, u, zeta, law(1000.0), keep=2)
    tab = make_history(MemoryConfig(kernel="tabulated", table=table), sum_rule, rule, src, k, steps)
    pro = make_history(MemoryConfig(kernel="exponential", weights=(-1.0, -0.5), times=(1.0, 0.3)), sum_rule, rule,
                       src, k, steps)
    assert isinstance(tab, PronyHistory) and tab.kernel_fit.terms == 2 and tab.kernel_fit.error <= 1e-8
    assert pro.kernel_fit is None and not hasattr(tab, "past")
    for n in range(steps):
        _drive(u, zeta, n)
        tab.commit(n)
        pro.commit(n)
        if sum_rule == "trapezoid_extrapolated":
            tab.extrapolate(None)
            pro.extrapolate(None)
        assert np.allclose(tab.M.x.array, pro.M.x.array, rtol=1e-12, atol=1e-12 * np.abs(pro.M.x.array).max())


def test_power_kernel_matches_the_direct_sum_with_the_exact_kernel(comm):
    """g(s) = 0.7 s^-0.5 as a sum of exponentials: M_n equals k sum_m g((n-m)k) H_m with the exact g to the kernel
    error the fit reports (the sum's terms are of one sign, so M's relative error is at most the kernel's)."""
    m, u, zeta, rule = _setup(comm)
    k, steps = 0.05, 12
    cfg = MemoryConfig(kernel="power", coefficient=0.7, exponent=0.5, kernel_tolerance=1e-9, L=150.0)
    hist = make_history(cfg, "left", rule, MemorySource(rule, u, zeta, law(cfg.L)), k, steps)
    fit = hist.kernel_fit
    assert isinstance(hist, PronyHistory) and fit.error <= 1e-9 and fit.terms == len(hist.weights) > 1
    probe = rule.evaluator(memory_source(u, zeta, A, cfg.L), hist.M.function_space)
    hs = []
    worst = 0.0
    for n in range(steps):
        _drive(u, zeta, n)
        hs.append(probe().copy())
        hist.commit(n)
        want = _direct(hs, lambda s: 0.7 * s ** -0.5, k, n + 1)
        bound = k * sum(0.7 * ((n + 1 - j) * k) ** -0.5 * np.abs(hs[j]) for j in range(n + 1))
        worst = max(worst, float(np.max(np.abs(hist.M.x.array - want) / np.maximum(bound, 1e-300))))
    worst = comm.allreduce(worst, op=MPI.MAX)
    assert worst <= fit.error * (1 + 1e-6) + 1e-14 and worst > 0


def test_power_kernel_refuses_a_trapezoid(comm):
    m, u, zeta, rule = _setup(comm)
    from solver.laws.kernels import KernelFitError
    with pytest.raises(KernelFitError, match="g\\(0\\)"):
        make_history(MemoryConfig(kernel="power"), "trapezoid", rule, MemorySource(rule, u, zeta, law(1000.0)), 0.1, 3)


def test_no_memory_builds_nothing(comm):
    m, u, zeta, rule = _setup(comm)
    assert make_history(MemoryConfig(kernel="none"), "left", rule, None, 0.1, 3) is None


def test_quadrature_layout_integrates_like_ufl(comm):
    """The quadrature function, filled through the dofmap (also on ghosts), integrates like the expression."""
    m, u, zeta, rule = _setup(comm, degree=2)
    _drive(u, zeta, 4)
    expr = zeta * A(strain(u))
    Q = rule.space((2, 2))
    q = fem.Function(Q)
    rule.evaluator(expr, Q)(q.x.array)
    V = fem.VectorFunctionSpace(m, ("CG", 1))
    w = fem.Function(V)
    w.interpolate(lambda x: np.vstack([x[0] * x[1], x[0] - x[1] ** 2]))
    a = fem.assemble_scalar(fem.form(ufl.inner(q, strain(w)) * rule.dx))
    b = fem.assemble_scalar(fem.form(ufl.inner(expr, strain(w)) * rule.dx))
    a, b = comm.allreduce(a, op=MPI.SUM), comm.allreduce(b, op=MPI.SUM)
    assert a == pytest.approx(b, rel=1e-12)


@pytest.mark.parametrize("degree", [1, 2])
@pytest.mark.parametrize("damage", [True, False])
def test_fast_source_equals_ufl_expression(comm, degree, damage):
    """MemorySource (sparse eps and zeta operators + numpy) against the UFL definition, truncation acting."""
    m, u, zeta, rule = _setup(comm, degree)
    z = zeta if damage else fem.Constant(m, 0.7)
    L = 150.0
    fast = MemorySource(rule, u, z, law(L))
    ref = rule.evaluator(memory_source(u, z, A, L), fast.Q)
    for n in (2, 5):
        _drive(u, zeta, n)
        a, b = fast(), ref()
        assert np.allclose(a, b, rtol=1e-13, atol=1e-12 * np.abs(b).max())
    raw = rule.evaluator(A(strain(u)), fast.Q)()
    assert comm.allreduce(np.abs(raw).max(), op=MPI.MAX) > L


@pytest.mark.parametrize("kernel", [{"kernel": "constant", "weights": [1.0]},
                                    {"kernel": "exponential", "weights": [-1.0], "times": [1.0]}])
def test_plane_strain_sigma_33_has_its_memory_part(comm, kernel):
    """Plane strain, uniaxial stress t (rollers on the left and the bottom): every field is uniform.
    sigma_33 = lambda tr eps(u_n) + M_33,n with M_33 the kernel's sum of zeta0 Phi_L(lambda tr eps(u_m)),
    truncated (L = 3 < lambda tr eps); the von Mises value includes it."""
    from solver.config import from_dict
    from solver.io.fields import CellStresses
    from solver.physics.material import von_mises_array
    from solver.run.model import build_model

    E, nu, t, k, L, zeta0 = 100.0, 0.3, 10.0, 0.1, 3.0, 0.8
    cfg = from_dict({
        "mesh": {"nx": 3, "ny": 2, "corners": [[0, 0], [2, 1]]}, "material": {"E": E, "nu": nu, "model": "plane_strain"},
        "boundary": {"left": {"role": "displacement", "displacement": [0.0, "free"]},
                     "bottom": {"role": "displacement", "displacement": ["free", 0.0]},
                     "right": {"role": "traction", "traction": [t, 0.0]}},
        "memory": {**kernel, "L": L}, "damage": {"enabled": False, "zeta0": zeta0}, "time": {"T": 0.4, "k": k}})
    model = build_model(cfg, comm)
    cells = CellStresses(model, cfg.material)
    lam, mu = lame(E, nu, "plane_strain")
    A2 = np.array([[lam + 2 * mu, lam], [lam, lam + 2 * mu]])
    g = (lambda s: 1.0) if kernel["kernel"] == "constant" else (lambda s: -math.exp(-s))
    H = []  # (H_xx, H_yy, H_33) of each level
    for n in range(cfg.time.steps + 1):
        model.mech.solve(n * k)
        M = k * sum(g((n - m) * k) * np.array(H[m]) for m in range(n)) if n else np.zeros(3)
        exx, eyy = np.linalg.solve(A2, [t - M[0], -M[1]])
        s33_el = lam * (exx + eyy)
        H.append(zeta0 * np.clip([t - M[0], -M[1], s33_el], -L, L))
        elastic = cells.elastic()
        zz, zz_el = cells.out_of_plane()
        vm = von_mises_array(cells.total(elastic), 2, zz)
        assert np.allclose(zz_el, s33_el, rtol=1e-10, atol=0), n
        assert np.allclose(zz, s33_el + M[2], rtol=1e-10, atol=0), n
        want_vm = von_mises_array(np.array([t, 0.0, 0.0, 0.0]), 2, np.array([s33_el + M[2]]))[0]
        assert np.allclose(vm, want_vm, rtol=1e-10, atol=0), n
        model.history.commit(n)
    assert abs(H[0][2]) == pytest.approx(zeta0 * L)  # the truncation of the 33 entry acted


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


@pytest.mark.parametrize("rule", ["trapezoid", "trapezoid_extrapolated"])
def test_level_0_is_the_elastic_problem_for_every_rule(comm, rule):
    """M_0 = 0: level 0 does not depend on the rule or on k: the implicit trapezoid's current term has weight 0 there."""
    from conftest import ROOT

    from solver.config import load
    from solver.run.model import build_model
    from solver.run.stepper import Stepper

    def level0(r, k):
        order = 2 if r == "trapezoid_extrapolated" else 1  # the extrapolated trapezoid is order 2's rule
        model = build_model(load(ROOT / "configs/example1.toml", ["mesh.nx=4", "mesh.ny=4", f"time.k={k}",
                                                                  f"time.order={order}", f"memory.rule='{r}'"]), comm)
        return Stepper(model).step(0)["strain_norm"]

    assert level0(rule, 0.1) == pytest.approx(level0("left", 0.1), rel=1e-12)
    assert level0(rule, 0.05) == pytest.approx(level0("left", 0.1), rel=1e-12)


@pytest.mark.parametrize("model_name", ["plane_stress", "plane_strain"])
def test_extrapolated_current_term_is_its_definition(comm, model_name):
    """time.order = 2, P2: after level n >= 2, M_n = P_n + (k/2) g(0) zeta_n Phi_L(A eps(u*)), u* = 2 u_{n-1} - u_{n-2},
    against the UFL definition with the truncation acting; in plane strain M_33 likewise with (A eps)_33 =
    lambda tr eps, set as well (M_33 not left at 0)."""
    from conftest import ROOT

    from solver.config import load
    from solver.run.model import build_model
    from solver.run.stepper import Stepper

    L, k = 5.0, 0.1
    cfg = load(ROOT / "configs/example1.toml", ["mesh.nx=3", "mesh.ny=3", "discretization.u_degree=2", "time.order=2",
                                                f"time.k={k}", "time.T=0.5", f"memory.L={L}",
                                                f"material.model='{model_name}'"])
    model = build_model(cfg, comm)
    hist = model.history
    assert hist.extrapolated and model.u_prev is not None
    main = hist.main if model_name == "plane_strain" else hist
    E, nu = cfg.material.E, cfg.material.nu
    lam = lame(E, nu, model_name)[0]
    ustar = fem.Function(model.u.function_space)
    rule = model.rule
    ref = rule.evaluator(memory_source(ustar, model.zeta, lambda e: elasticity(e, E, nu, model_name), L),
                         main.M.function_space)
    raw = rule.evaluator(elasticity(strain(ustar), E, nu, model_name), main.M.function_space)
    ref33 = rule.evaluator(model.zeta * ufl.max_value(-L, ufl.min_value(L, lam * ufl.tr(strain(ustar)))), rule.space(()))
    weight = 0.5 * k * main.g0
    stepper = Stepper(model)
    us, acted = [], False
    for n in range(5):
        stepper.step(n)
        if n >= 2:
            ustar.x.array[:] = 2.0 * us[n - 1] - us[n - 2]
            want = main.P + weight * ref()
            assert np.allclose(main.M.x.array, want, rtol=1e-12, atol=1e-12 * np.abs(want).max()), n
            acted |= comm.allreduce(np.abs(raw()).max(), op=MPI.MAX) > L
            if model_name == "plane_strain":
                zz = hist.out_of_plane
                want33 = zz.P + weight * ref33()
                assert np.allclose(zz.M.x.array, want33, rtol=1e-12, atol=1e-12 * np.abs(want33).max()), n
                assert comm.allreduce(np.abs(zz.M.x.array).max(), op=MPI.MAX) > 0.0
        us.append(model.u.x.array.copy())
    assert acted


@pytest.mark.parametrize("keep", [0, 2])
def test_extrapolated_source_from_kept_strains(comm, keep):
    """H(2 u - u_prev) by linearity of the strain equals the UFL definition at u* (truncation acting), and the
    same bits whether the strains were kept or computed afresh (a restart keeps none)."""
    m, u, zeta, rule = _setup(comm, 2)
    u = fem.Function(fem.VectorFunctionSpace(m, ("CG", 2)))
    L = 150.0
    fast = MemorySource(rule, u, zeta, law(L), keep=keep)
    fresh = MemorySource(rule, u, zeta, law(L))
    ustar = fem.Function(u.function_space)
    ref = rule.evaluator(memory_source(ustar, zeta, A, L), fast.Q)
    _drive(u, zeta, 2)
    fast()
    u_prev = u.x.array.copy()
    _drive(u, zeta, 5)
    fast()
    ustar.x.array[:] = 2.0 * u.x.array - u_prev
    a, b = fast.extrapolated(u_prev), ref()
    assert np.allclose(a, b, rtol=1e-12, atol=1e-12 * np.abs(b).max())
    assert np.array_equal(a, fresh.extrapolated(u_prev))
    assert len(fast._cache) == keep
    raw = rule.evaluator(A(strain(ustar)), fast.Q)()
    assert comm.allreduce(np.abs(raw).max(), op=MPI.MAX) > L


def test_equal_is_exact():
    """The kept-strain lookup's comparison: a sample first, then every entry."""
    from solver.physics.memory_source import _equal

    a = np.arange(1000.0)
    b = a.copy()
    assert _equal(a, b)
    b[7] += 1e-13  # off the sample
    assert not _equal(a, b)
    assert not _equal(a, a[:-1]) and _equal(a[:0], b[:0])


@pytest.mark.parametrize("values,finite", [([1.0, -2.0, 3.0], True), ([], True), ([1e308, 1e308], True),
                                           ([1.0, np.nan], False), ([np.inf, 1.0], False), ([-np.inf, np.inf], False),
                                           ([1e308, 1e308, np.nan], False)])
def test_all_finite_decides_like_isfinite(values, finite):
    """The one-sum NaN/inf test: an overflow of finite entries is not mistaken for an infinite one."""
    from solver.physics.quadrature import all_finite

    a = np.array(values, dtype=float)
    assert all_finite(a) is finite
    assert finite == bool(np.all(np.isfinite(a)))


def test_history_finite_sees_what_was_written_through_state(comm):
    """PronyHistory.finite() uses the sum taken at the commit; a NaN written through state() (a checkpoint) is seen."""
    cfg, _ = KERNELS["constant"]
    m, u, zeta, rule = _setup(comm)
    hist = make_history(cfg, "left", rule, MemorySource(rule, u, zeta, law(cfg.L)), 0.1, 3)
    _drive(u, zeta, 1)
    hist.commit(0)
    assert hist.finite()
    hist.state()["M"][0] = np.nan
    assert not hist.finite()
    hist.M.x.array[0] = 0.0
    hist.commit(1)
    assert hist.finite()


def test_every_configured_rule_is_a_sum_rule():
    """Each memory.rule the config resolves to has its SumRule: H_0 at weight 1 (left) or 1/2 (trapezoids), the
    past kept apart only by the extrapolated trapezoid, the current term implicit only in the plain trapezoid."""
    from solver.config.memory import RULES
    from solver.physics.memory import SUM_RULES

    assert set(SUM_RULES) == set(RULES) - {"auto"}
    assert {name: (r.first_weight, r.extrapolated, r.implicit) for name, r in SUM_RULES.items()} == {
        "left": (1.0, False, False), "trapezoid": (0.5, False, True), "trapezoid_extrapolated": (0.5, True, False)}


@pytest.mark.parametrize("sum_rule", ["left", "trapezoid", "trapezoid_extrapolated"])
def test_only_the_implicit_trapezoid_has_a_current_weight_and_its_term_leaves_the_history_alone(comm, sum_rule):
    """The weight of the implicit current-level term is the history's own, declared at construction (0 until the
    first commit, (k/2) g(0) after); trapezoid_term reads it and changes nothing; other rules have none."""
    cfg, _ = KERNELS["prony3"]
    m, u, zeta, rule = _setup(comm)
    hist = make_history(cfg, sum_rule, rule, MemorySource(rule, u, zeta, law(cfg.L)), 0.1, 3)
    if sum_rule != "trapezoid":
        assert hist.current_weight is None
        with pytest.raises(ValueError, match=sum_rule):
            trapezoid_term(hist, law(cfg.L), zeta)
        return
    weight = hist.current_weight
    assert float(weight.value) == 0.0
    term = trapezoid_term(hist, law(cfg.L), zeta)
    assert hist.current_weight is weight and float(weight.value) == 0.0
    _drive(u, zeta, 1)
    hist.commit(0)
    assert float(weight.value) == 0.5 * 0.1 * sum(cfg.weights)
    w = ufl.TestFunction(u.function_space)
    form = fem.form(term(u, w))  # the weight is a constant of the form: the commit's value, not a copy
    b = fpetsc.assemble_vector(form)
    b.ghostUpdate(addv=PETSc.InsertMode.ADD, mode=PETSc.ScatterMode.REVERSE)
    H = law(cfg.L).ufl(strain(u), zeta)
    want = fpetsc.assemble_vector(fem.form(float(weight.value) * ufl.inner(H, strain(w)) * rule.dx))
    want.ghostUpdate(addv=PETSc.InsertMode.ADD, mode=PETSc.ScatterMode.REVERSE)
    assert np.allclose(b.array_r, want.array_r, rtol=1e-13, atol=1e-13 * np.abs(want.array_r).max())
