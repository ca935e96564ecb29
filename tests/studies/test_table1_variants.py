"""The Table 1 measurement variants: each reading is consistent with the others and with the Table 1 study."""

import json

import numpy as np
import pytest
from conftest import ROOT
from mpi4py import MPI

from solver.errors import UsageError
from studies.convergence import Fields, Reference
from studies.table1_variants import (
    FORMS,
    U_FORMS,
    VARIANTS,
    Measurement,
    Measurer,
    evaluate,
    injection,
    study,
    summary,
    write,
)

pytestmark = pytest.mark.serial  # like the Table 1 study: one process

CFG = ROOT / "configs/example1.toml"
N_REF, K_REF, KS = 8, 0.05, [0.05, 0.1, 0.2]


@pytest.fixture(scope="module")
def measurer(tmp_path_factory):
    ref = Reference(CFG, N_REF, K_REF, KS, tmp_path_factory.mktemp("cache"), [])
    return Measurer(ref)


@pytest.fixture(scope="module")
def runs(measurer):
    """Series of a few coarse runs: (n, k, initial) -> series."""
    return {(n, k, init): measurer.run(n, k, init)[0] for n in (2, 4) for k in (0.1, 0.2)
            for init in ("elastic", "interpolant")}


@pytest.mark.parametrize("n, k", [(2, 0.1), (4, 0.1), (4, 0.2)])
def test_default_reproduces_the_table1_study(measurer, runs, n, k):
    rec, _ = measurer.ref.measure([], n, k)
    got = evaluate(runs[n, k, "elastic"], Measurement(), k)
    assert got["error"] == rec["error"] and got["error_u"] == rec["error_u"]
    assert got["error_zeta"] == rec["error_zeta"] and got["t_max"] == rec["t_max"]
    no0 = evaluate(runs[n, k, "elastic"], Measurement(level0=False), k)
    assert no0["error"] == rec["error_after_t0"]


def test_reference_mesh_measured_against_itself_is_zero(measurer):
    """The coarse run at the reference's own n and k is the reference: zero in every transfer and sampling."""
    series, _ = measurer.run(N_REF, K_REF)
    for key in series.t:
        _, F = series.arrays(*key)
        assert np.abs(F).max() <= 1e-12, key


def test_u0_interpolant_makes_the_restricted_t0_error_vanish(runs):
    for n, k in [(2, 0.1), (4, 0.2)]:
        t, F = runs[n, k, "interpolant"].arrays("restrict", "coarse")
        assert t[0] == 0.0 and np.all(F[0] == 0.0)
        _, Fp = runs[n, k, "interpolant"].arrays("prolong", "coarse")
        assert Fp[0, 0] > 0  # on the fine mesh the interpolation error stays
        _, Fe = runs[n, k, "elastic"].arrays("restrict", "coarse")
        assert Fe[0, 0] > 0 and F[1:, 0].max() > 0  # the elastic solve is not the interpolant; the run moves on


def test_norms_are_ordered(runs):
    """||grad v||^2 = ||eps(v)||^2 + ||skew grad v||^2; H1 >= seminorm; voigt <= eps <= engineering."""
    ms = {name: Measurement(u_norm=name) for name in ("eps_voigt", "eps", "eps_engineering", "h1_semi", "h1")}
    for series in runs.values():
        for key in series.t:
            _, F = series.arrays(*key)
            # Squared norms of differences, some computed expanded (a.Qa - 2 a.Qb + b.Qb, the sampled levels): their
            # round-off is relative to the operands' squared norms, not to the difference's. For u those are of the
            # size of F's largest entry here; for zeta (0 <= zeta <= 1 on the unit square) ||zeta||^2 <= 1, and an
            # l2z of -2.2e-16 at t = 0 (two equal fields) was seen in a fresh image while F's largest was 5.7e-3.
            scale = np.where(np.arange(F.shape[1]) < U_FORMS, np.abs(F).max(), max(np.abs(F).max(), 1.0))
            assert np.all(F >= -1e-14 * scale)
            # ... to round-off: at t = 0 both are differences of equal fields (1e-17 with OpenBLAS, where grad gave 0)
            assert np.all(F[:, FORMS.index("grad")] >= F[:, FORMS.index("eps")] * (1 - 1e-12) - 1e-14 * np.abs(F).max())
        for k in (0.1, 0.2):
            e = {name: evaluate(series, m, k)["error_u"] for name, m in ms.items()}
            assert e["eps_voigt"] <= e["eps"] <= e["eps_engineering"] and e["eps"] <= e["h1_semi"] <= e["h1"]
            assert (evaluate(series, Measurement(zeta_norm="h1"), k)["error"]
                    >= evaluate(series, Measurement(), k)["error"])
            assert (evaluate(series, Measurement(combine="sum_max"), k)["error"]
                    >= evaluate(series, Measurement(), k)["error"])


def test_samples_between_levels_equal_a_direct_computation(measurer):
    """The held and interpolated samples (expanded quadratic forms) against differences formed directly."""
    from solver.config import load
    from solver.io.results import run
    from solver.run.model import build_model

    n, k = 4, 0.2
    ref = measurer.ref
    series, _ = measurer.run(n, k)
    model = build_model(load(CFG, [f"mesh.nx={n}", f"mesh.ny={n}", f"time.k={k}", "output.xdmf=false"]), MPI.COMM_SELF)
    flds = Fields(model, n)
    levels = []
    run(model, on_step=lambda row: levels.append((flds.u(), flds.zeta())))
    m = round(k / K_REF)
    for transfer in ("prolong", "restrict"):
        space = measurer.space(transfer, n)
        t_c, F_c = series.arrays(transfer, "coarse")
        for sampling in ("hold", "hold_next", "interpolate"):
            t, F = series.arrays(transfer, sampling)
            assert np.allclose(t, ref.times)  # every stored reference level, once
            for s, ts in enumerate(t):
                j, r = divmod(round(ts / K_REF), m)
                theta = {"hold": 0.0, "hold_next": float(r > 0), "interpolate": r / m}[sampling]
                u = levels[j][0] if theta == 0 else (1 - theta) * levels[j][0] + theta * levels[j + 1][0]
                z = levels[j][1] if theta == 0 else (1 - theta) * levels[j][1] + theta * levels[j + 1][1]
                bu, bz = space.coarse(u, z)
                au, az = space.ref_block(s, s + 1)
                direct = space.forms(au[0] - bu, az[0] - bz)
                assert F[s] == pytest.approx(direct, rel=1e-9, abs=1e-13 * np.abs(space.ref_forms()[s]).max())
                if r == 0:  # at a coarse level: the coarse sample
                    assert F[s] == pytest.approx(F_c[j], rel=1e-9, abs=1e-15)


def test_restriction_is_nodal_interpolation():
    idx = injection(2, 8)
    row, col = np.divmod(idx, 9)
    assert np.array_equal(col, np.tile([0, 4, 8], 3)) and np.array_equal(row, np.repeat([0, 4, 8], 3))


def test_measurement_refuses_unknown_choices():
    with pytest.raises(UsageError):
        Measurement(transfer="sideways")
    assert Measurement().label() == "default"
    assert Measurement(transfer="restrict", level0=False).label() == "transfer=restrict+level0=False"
    assert Measurement(initial="interpolant", diagonal="left").run_key == ("interpolant", "left")


def test_study_writes_every_variant(tmp_path):
    named = {name: VARIANTS[name] for name in ("ours", "restrict", "u0-interpolant", "left-diagonal")}
    result = study(CFG, named, [4, 8], [0.05], 16, 0.025, tmp_path / "cache", log=lambda *_: None)
    assert {r["diagonal"] for r in result["references"]} == {"right", "left"}
    assert all(len(rows) == 2 for rows in result["named"].values())
    assert len(result["search"]) == 3 * 320  # every measurement-only combination, for each of the three runs
    assert result["search"]["default"] == result["named"]["ours"]
    summ = write(result, tmp_path, "test")
    doc = json.loads((tmp_path / "table1_variants.json").read_text())
    assert set(doc["named"]) == set(named)
    s = summary(result["named"]["ours"])
    assert s["entries"] == 2 and s["min_ratio"] <= s["median_ratio"] <= s["max_ratio"]
    md = (tmp_path / "table1_variants.md").read_text()
    assert summ["best_named"] in md and "| 4 |" in md
    lines = (tmp_path / "table1_variants.csv").read_text().splitlines()
    assert len(lines) == 1 + 2 * (len(named) + 10)
    left = result["named"]["left-diagonal"]
    assert left[0]["error"] != result["named"]["ours"][0]["error"]


@pytest.mark.parametrize("argv", [["--ns", "3", "--ref-n", "8"], ["--ks", "0.0007"]])
def test_cli_refuses_non_nested_grids(argv, capsys, tmp_path):
    from studies.study import main

    assert main(["table1-variants", *argv, "--output", str(tmp_path), "--cache", str(tmp_path)]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and err[0].startswith("error:")


def test_u_forms_first():
    assert FORMS[:U_FORMS] == ("eps", "shear", "grad", "l2u")
