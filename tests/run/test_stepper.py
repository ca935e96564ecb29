"""The time loop: which levels are written, the order of a step, and failures that know their step."""

import time

import numpy as np
import pytest
from conftest import ROOT, solve

from solver.config import from_dict
from solver.errors import DisplacementSolveError
from solver.io.results import _csv_lines_until, run
from solver.run.model import build_model
from solver.run.scheme import FirstOrderScheme, SecondOrderScheme
from solver.run.stepper import Stepper, writes_level

SCENE = {"mesh": {"nx": 4, "ny": 4}, "time": {"T": 0.3, "k": 0.1}}


def test_writes_level():
    assert [n for n in range(11) if writes_level(n, 10, 3)] == [0, 3, 6, 9, 10]
    assert [n for n in range(11) if writes_level(n, 10, 0)] == [0, 10]
    assert all(writes_level(n, 10, 1) for n in range(11))


def test_written_levels_counts_what_writes_level_writes():
    from solver.run.stepper import written_levels

    for steps in (0, 1, 7, 10, 100):
        for every in (0, 1, 3, 7, 100):
            for first in range(steps + 1):
                for last in range(first - 1, steps + 1):
                    expected = sum(writes_level(n, steps, every) for n in range(first, last + 1))
                    assert written_levels(first, last, steps, every) == expected, (steps, every, first, last)


@pytest.mark.parametrize("every", [1, 3])
def test_a_run_sizes_its_chunks_to_the_checkpoints_and_writes_each_once(comm, tmp_path_factory, monkeypatch, every):
    """A chunk of the series opened at a level holds the levels written up to the next checkpoint (whose flush
    closes it) or the last level: none is closed early and written again, and every level is listed."""
    import solver.io.xdmf as sx
    from solver.post.results import read_results

    rewrites = []
    monkeypatch.setattr(sx, "MAX_LEVELS_PER_CHUNK", 3)
    monkeypatch.setattr(sx._Chunk, "_rewrite", lambda self, n: rewrites.append(n))
    out = tmp_path_factory.mktemp("chunks") if comm.rank == 0 else None
    out = comm.bcast(out, root=0)
    cfg = from_dict({"mesh": {"nx": 4, "ny": 4}, "time": {"T": 1.0, "k": 0.1},
                     "output": {"every": every, "checkpoint_every": 4}})
    from solver.io.layout import prepare

    prepare(comm, out / "run")
    solve(cfg, comm, out / "run")
    assert rewrites == []
    written = [n for n in range(11) if writes_level(n, 10, every)]
    assert read_results(out / "run")["times"] == pytest.approx([0.1 * n for n in written])


def test_a_step_commits_the_memory_of_the_previous_level_first(comm):
    """Level 1 uses M_1 = k g(k) H(u_0, zeta_0): the history is formed from level 0 before the damage moves."""
    model = build_model(from_dict(SCENE), comm)
    stepper = Stepper(model)
    row0 = stepper.step(0)
    assert np.all(model.history.M.x.array == 0.0)  # M_0 = 0: nothing committed at level 0
    H0 = model.history.H().copy()  # H(u_0, zeta_0)
    stepper.step(1)
    assert np.allclose(model.history.M.x.array, 0.1 * 1.0 * H0, rtol=0, atol=1e-14 * np.abs(H0).max())
    assert row0["step"] == 0 and row0["zeta_min"] == 1.0


def test_the_timings_of_a_step_are_its_phases_in_seconds(comm):
    """Level 2 does work in every phase (memory, damage, displacement, diagnostics): each is timed (> 0), and the
    phases are disjoint parts of the step, so together they fit in the wall-clock time around it and make most
    of it."""
    stepper = Stepper(build_model(from_dict(SCENE), comm))
    stepper.step(0)
    stepper.step(1)
    before = time.perf_counter()
    row = stepper.step(2)
    elapsed = time.perf_counter() - before
    parts = [row[key] for key in ("time_memory", "time_damage", "time_displacement", "time_diagnostics")]
    assert all(p > 0.0 for p in parts), parts
    assert 0.5 * elapsed <= sum(parts) <= elapsed, (parts, elapsed)


@pytest.mark.parametrize("order,cls", [(1, FirstOrderScheme), (2, SecondOrderScheme)])
def test_the_time_scheme_follows_the_order(comm, order, cls):
    """Order 2: the first level is Heun's predictor-corrector (two displacement solves, zeta_1 corrected);
    later levels and order 1 solve once."""
    model = build_model(from_dict({**SCENE, "time": {**SCENE["time"], "order": order}}), comm)
    stepper = Stepper(model)
    assert type(stepper.scheme) is cls
    solves = [stepper.step(n)["linear_solves"] for n in range(3)]
    heun = order == 2
    assert (model.u_prev is not None) == heun
    assert (solves[1] > solves[2]) == heun  # the elastic-contact levels take the same count per solve here
    if heun:
        assert model.damage._zeta0 is None and model.damage.have_prev


def test_run_rows_have_every_timing_and_a_wall_time_that_sums_them(comm):
    _, rows = solve(from_dict(SCENE), comm)
    assert [r["step"] for r in rows] == [0, 1, 2, 3]
    parts = ("time_memory", "time_damage", "time_displacement", "time_diagnostics", "time_output")
    for r in rows:
        assert r["wall_time"] == pytest.approx(sum(r[p] for p in parts), rel=1e-12)


def test_a_failure_carries_the_step_and_time(comm, monkeypatch):
    model = build_model(from_dict(SCENE), comm)
    stepper = Stepper(model)
    stepper.step(0)

    def fail(t):
        raise DisplacementSolveError("SNES", "DIVERGED_MAX_IT", 3, [1.0], 1e-10)

    monkeypatch.setattr(model.mech, "solve", fail)
    with pytest.raises(DisplacementSolveError) as err:
        stepper.step(2)
    assert (err.value.step, err.value.t) == (2, pytest.approx(0.2))


def test_csv_lines_until_keeps_complete_rows_up_to_a_step(tmp_path):
    path = tmp_path / "t.csv"
    path.write_text("step,t\n0,0.0\n1,0.1\n2,0.2\n3,0.")  # the last row was cut by a kill
    assert _csv_lines_until(path, 1) == ["0,0.0\n", "1,0.1\n"]
    assert _csv_lines_until(path, 9) == ["0,0.0\n", "1,0.1\n", "2,0.2\n"]
    assert _csv_lines_until(tmp_path / "none.csv", 3) == []


def _paper_norm_errors(comm, order: int, ks, k_ref: float) -> list[float]:
    """max over levels of ||eps(u - u_ref)|| + ||zeta - zeta_ref|| on Example 1 at n = 8 (the same mesh: time error only)."""
    import dolfinx.fem.petsc  # noqa: F401
    import ufl
    from dolfinx import fem
    from mpi4py import MPI

    from solver.config import load

    def levels(k):
        cfg = load(ROOT / "configs/example1.toml", ["mesh.nx=8", "mesh.ny=8", f"time.order={order}", f"time.k={k}"])
        model = build_model(cfg, comm)
        out = {}
        run(model, on_step=lambda r: out.__setitem__(round(r["t"], 9), (model.u.x.array.copy(),
                                                                        model.damage.zeta.x.array.copy())))
        return model, out

    model, ref = levels(k_ref)
    V, Z = model.u.function_space, model.damage.V
    err_u = fem.Function(V)
    err_z = fem.Function(Z)
    e = ufl.sym(ufl.grad(err_u))
    forms = fem.form(ufl.inner(e, e) * ufl.dx), fem.form(err_z * err_z * ufl.dx)
    out = []
    for k in ks:
        _, sol = levels(k)
        worst = 0.0
        for t, (u, z) in sol.items():
            err_u.x.array[:] = u - ref[t][0]
            err_z.x.array[:] = z - ref[t][1]
            a, b = (np.sqrt(comm.allreduce(fem.assemble_scalar(f), op=MPI.SUM)) for f in forms)
            worst = max(worst, a + b)
        out.append(worst)
    return out


@pytest.mark.parametrize("order,low,high", [(1, 0.9, 1.3), (2, 1.8, 2.2)])
def test_observed_order_in_k(comm, order, low, high):
    """Against the same scheme at k/64 on the same mesh: order 1 stays first order, order 2 is second order."""
    ks = [0.1, 0.05, 0.025]
    errs = _paper_norm_errors(comm, order, ks, 0.1 / 64)
    rates = [np.log2(a / b) for a, b in zip(errs, errs[1:])]
    assert all(low <= r <= high for r in rates), (errs, rates)



def _final_errors_of_variable_steps(comm, order: int, counts, k_ref: float, seed: int = 41) -> list[float]:
    """||eps(u - u_ref)|| + ||zeta - zeta_ref|| at T of Example 1 (n = 8, T = 0.5) for steps drawn at random within
    2x of each other (N of them for each N in ``counts``), against uniform steps k_ref on the same mesh."""
    import dolfinx.fem.petsc  # noqa: F401
    import ufl
    from dolfinx import fem
    from mpi4py import MPI

    from solver.config import load
    from solver.run.stepper import levels

    T = 0.5
    sets = ["mesh.nx=8", "mesh.ny=8", f"time.order={order}", f"time.T={T}"]

    def final(k, times=None):
        model = build_model(load(ROOT / "configs/example1.toml", [*sets, f"time.k={k}"]), comm)
        rows = list(levels(model, times=times))
        assert abs(rows[-1]["t"] - T) < 1e-12
        return model, model.u.x.array.copy(), model.damage.zeta.x.array.copy()

    model, u_ref, z_ref = final(k_ref)
    err_u, err_z = fem.Function(model.u.function_space), fem.Function(model.damage.V)
    e = ufl.sym(ufl.grad(err_u))
    forms = fem.form(ufl.inner(e, e) * ufl.dx), fem.form(err_z * err_z * ufl.dx)
    rng = np.random.default_rng(seed)
    out = []
    for count in counts:
        steps = rng.uniform(1.0, 2.0, count)
        times = np.concatenate([[0.0], np.cumsum(steps) * (T / steps.sum())])
        times[-1] = T
        _, u, z = final(T / count, times)
        err_u.x.array[:] = u - u_ref
        err_z.x.array[:] = z - z_ref
        out.append(sum(np.sqrt(comm.allreduce(fem.assemble_scalar(f), op=MPI.SUM)) for f in forms))
    return out


@pytest.mark.parametrize("order,low,high", [(1, 0.8, 1.3), (2, 1.7, 2.3)])
def test_random_variable_steps_converge_at_the_schemes_order(comm, order, low, high):
    """Steps within 2x of each other, drawn at random, against uniform steps T/1280: the error at T falls at the
    scheme's order as their number doubles (the variable-step memory sum, damage step and extrapolation)."""
    errs = _final_errors_of_variable_steps(comm, order, [10, 20, 40, 80], 0.5 / 1280)
    rates = [np.log2(a / b) for a, b in zip(errs, errs[1:])]
    assert all(low <= r <= high for r in rates), (errs, rates)


def test_uniform_times_given_as_variable_steps_give_the_uniform_run(comm):
    """Levels at t_n = n k passed as times: the same numbers as the uniform run (k_n computed as differences)."""
    from solver.config import load
    from solver.run.stepper import levels

    cfg = load(ROOT / "configs/example1.toml", ["mesh.nx=8", "mesh.ny=8", "time.order=2", "time.T=0.2",
                                                "time.k=0.05"])
    a = build_model(cfg, comm)
    ra = list(levels(a))
    b = build_model(cfg, comm)
    rb = list(levels(b, times=[n * 0.05 for n in range(5)]))
    assert [r["contact_force"] for r in ra] == pytest.approx([r["contact_force"] for r in rb], rel=1e-12)
    assert np.allclose(a.u.x.array, b.u.x.array, rtol=1e-12, atol=1e-15)
