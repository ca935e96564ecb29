"""The scaling benchmark (bench --scaling): one case, predictions and skips, fits, the files it writes."""

import json

import numpy as np
import pytest
from conftest import run_cli

from studies import blas, scaling


def test_a_case_reports_its_figures_on_every_rank(comm):
    case = scaling.run_case(2, "iterative", 1)
    assert case["dofs"] == scaling.dofs_of(2) == 81 and case["cells"] == 6 * 8 and case["nproc"] == comm.size
    assert case["resolved"] == "iterative" and case["krylov_per_solve"] >= 1 and case["level0_krylov_per_solve"] >= 1
    assert case["peak_mib_sum"] >= case["peak_mib_max"] > 0
    assert set(case["split_ms"]) == set(scaling.PHASES) and case["step_s"] > 0
    assert comm.allgather(case["contact_force"]) == [case["contact_force"]] * comm.size
    direct = scaling.run_case(2, "mumps", 1)
    assert direct["krylov_per_solve"] is None
    assert direct["contact_force"] == pytest.approx(case["contact_force"], rel=1e-9)


def test_the_default_run_covers_one_cycle_of_the_initial_guess_at_every_size(monkeypatch):
    """10 steps, the solutions Fischer's projection keeps (linear.GUESS), at small and large sizes alike; the step is
    the mean of the run's steps, which differ by design (the first ones, before any projection, are the dearest)."""
    from solver.solvers import linear

    assert linear.GUESS["ksp_guess_fischer_model"] == "1,10"
    assert scaling.default_steps(14) == scaling.default_steps(68) == 10
    monkeypatch.setitem(linear.GUESS, "ksp_guess_fischer_model", "1,7")
    assert scaling.default_steps(46) == 7
    walls = [4.0, 1.0, 2.0, 3.0, 0.5]  # level 0, then the steps: mean 1.625, median 1.5
    rows = [{"wall_time": w, "newton_iterations": 1, "linear_solves": 1, "krylov_iterations": 1, "factorizations": 1,
             "damage_krylov_iterations": 1, "contact_force": 1.0, **{f"time_{p}": w for p in scaling.PHASES}}
            for w in walls]
    monkeypatch.setattr("solver.io.results.run", lambda model, out: rows)
    case = scaling.run_case(2, "iterative", 4)
    assert case["step_s"] == pytest.approx(1.625) and case["split_ms"]["damage"] == pytest.approx(1625.0)


def _case(solver, nproc, n, **kw):
    c = {"n": n, "solver": solver, "nproc": nproc, "steps": 3, "dofs": scaling.dofs_of(n), "status": "ok",
         "setup_s": 1.0, "level0_s": 10.0, "step_s": 0.1, "peak_mib_sum": 100.0 * nproc + 1000.0, "peak_mib_max": 1100.0}
    c.update(kw)
    return c


def test_prediction_from_the_largest_smaller_case_with_the_larger_of_measured_and_theory_exponents():
    cases = {scaling.key("mumps", 1, 10): _case("mumps", 1, 10)}
    p = scaling.predict(cases, "mumps", 1, 21, steps=3)
    r = scaling.dofs_of(21) / scaling.dofs_of(10)
    assert p["from_n"] == 10 and p["level0_s"] == pytest.approx(10.0 * r**2)  # one case: theory, N^2
    assert p["peak_mib_sum"] == pytest.approx(100.0 + 1000.0 * r ** (4 / 3))  # the base is not scaled
    assert p["total_s"] == pytest.approx(1.0 * r + p["level0_s"] + 3 * 0.1 * r ** (4 / 3))
    # two cases: a measured level-0 exponent of 3 beats the theory's 2
    r2 = scaling.dofs_of(10) / scaling.dofs_of(5)
    cases[scaling.key("mumps", 1, 5)] = _case("mumps", 1, 5, level0_s=10.0 / r2**3)
    assert scaling.predict(cases, "mumps", 1, 21, 3)["level0_s"] == pytest.approx(10.0 * r**3)
    assert scaling.predict(cases, "mumps", 2, 21, 3) is None  # other ranks: nothing to predict from
    assert scaling.predict(cases, "mumps", 1, 5, 3) is None  # nothing smaller


def test_skip_reasons_name_the_prediction_and_the_budget():
    pred = {"from_n": 32, "total_s": 1234.0, "peak_mib_sum": 2048.0}
    assert scaling.skip_reason(pred, budget_s=600, budget_mib=1e6).startswith("predicted 1234 s > budget 600 s")
    assert "2.0 GiB > budget 1.0 GiB" in scaling.skip_reason(dict(pred, total_s=1.0), budget_s=600, budget_mib=1024)
    assert scaling.skip_reason(dict(pred, total_s=1.0), 600, 1e6) is None and scaling.skip_reason(None, 1, 1) is None


def test_fit_recovers_a_power_law_in_dofs_and_ranks():
    a, b, c = 2e-6, 1.25, 0.8
    cases = [_case("iterative", R, n, step_s=a * scaling.dofs_of(n) ** b / R**c) for n in (20, 30, 45) for R in (1, 2)]
    f = scaling.fit_power(cases)
    assert f["a"] == pytest.approx(a, rel=1e-9) and f["b"] == pytest.approx(b) and f["c"] == pytest.approx(c)
    assert f["c_fitted"] and f["rms_log_error"] < 1e-9 and f["ranks"] == [1, 2]
    one = scaling.fit_power([x for x in cases if x["nproc"] == 1])
    assert not one["c_fitted"] and one["c"] == 0.0 and one["b"] == pytest.approx(b)
    assert scaling.fit_power(cases[:2]) is None  # one size: no exponent
    mem = scaling.fit_memory([_case("iterative", R, n, peak_mib_sum=90.0 * R + 3e-3 * scaling.dofs_of(n))
                              for n in (20, 30) for R in (1, 2)])
    assert mem["per_rank_mib"] == pytest.approx(90.0) and mem["bytes_per_dof"] == pytest.approx(3e-3 * 2**20)
    e = scaling.extrapolate({"step_s": f, "level0_s": None, "memory": mem}, 1e7, 100)
    assert e["step_s"] == pytest.approx(a * 1e7**b / 100**c) and e["level0_s"] is None
    assert e["memory_gib_total"] == pytest.approx((9000.0 + 3e4) / 1024)


def test_readme_block_is_replaced_between_its_markers_only(tmp_path):
    readme = tmp_path / "README.md"
    readme.write_text(f"intro\n{scaling.README_BEGIN}\nold numbers\n{scaling.README_END}\nafter\n")
    assert scaling.update_readme(readme, f"{scaling.README_BEGIN}\nnew\n{scaling.README_END}")
    assert readme.read_text() == f"intro\n{scaling.README_BEGIN}\nnew\n{scaling.README_END}\nafter\n"
    plain = tmp_path / "OTHER.md"
    plain.write_text("no markers\n")
    assert not scaling.update_readme(plain, "x") and plain.read_text() == "no markers\n"


def test_table_lists_skipped_cases_with_their_reason_and_the_speedups():
    cases = {scaling.key("iterative", R, 20): _case("iterative", R, 20, step_s=0.2 / R, level0_s=4.0 / R,
                                                     split_ms=dict.fromkeys(scaling.PHASES, 1.0), newton_per_step=1.0,
                                                     krylov_per_solve=30.0, level0_krylov_per_solve=40.0,
                                                     setups_total=2, contact_force=12.0)
             for R in (1, 2)}
    cases["mumps/np1/n68"] = {"n": 68, "solver": "mumps", "nproc": 1, "steps": 3, "dofs": scaling.dofs_of(68),
                              "status": "skipped", "reason": "predicted 9999 s > budget 600 s (from n = 32)"}
    cases["mumps/np1/n20"] = _case("mumps", 1, 20, step_s=0.05, level0_s=20.0, split_ms=dict.fromkeys(scaling.PHASES, 1.0),
                                   newton_per_step=1.0, krylov_per_solve=None, setups_total=2, contact_force=12.0)
    text = scaling.table({"cases": cases, "fit": scaling.fits(cases)})
    # 50 steps: 1 + 20 + 50 x 0.05 against 1 + 4 + 50 x 0.2; the direct run is faster from (21 - 5) / 0.15 steps
    assert "| 20 | 27,783 | 1 | mumps | 23.5 | 15.0 | 107 |" in text
    assert "| 68 | 985,527 | mumps | 1 | 3 |" in text and "skipped: predicted 9999 s > budget 600 s" in text
    assert "| 20 | 27,783 | iterative | 200.0 | 100.0 | 2.00 | 2.00 |" in text
    rows = [ln for ln in text.splitlines() if ln.startswith("| 20 | 27,783 | iterative | ")]
    assert [ln.count("|") for ln in rows] == [21, 21, 8]  # two cases with 20 columns, one speed-up row


@pytest.mark.serial
@pytest.mark.slow
def test_bench_scaling_writes_its_files_merges_bench_json_and_resumes(tmp_path):
    (tmp_path / "bench.json").write_text(json.dumps({"sizes": [{"n": 32}], "date": "earlier"}))
    args = ["bench", "--scaling", "--sizes", "2", "3", "--solvers", "iterative", "--nproc", "1", "2", "--steps", "1",
            "--output", str(tmp_path), "--allow-reference-blas"]
    res = run_cli(args)
    assert res.returncode == 0, res.stderr
    data = json.loads((tmp_path / "bench.json").read_text())
    assert data["sizes"] == [{"n": 32}] and data["date"] == "earlier"  # the time-loop benchmark's part is kept
    cases = data["scaling"]["cases"]
    assert sorted(cases) == ["iterative/np1/n2", "iterative/np1/n3", "iterative/np2/n2", "iterative/np2/n3"]
    assert all(c["status"] == "ok" and c["steps"] == 1 for c in cases.values())
    assert np.isclose(cases["iterative/np1/n3"]["contact_force"], cases["iterative/np2/n3"]["contact_force"], rtol=1e-9)
    # each case again as `solver run` with its outputs and a checkpoint: its peak and step
    assert all(c["cli_status"] == "ok" and c["cli_peak_mib_max"] > 50 and c["cli_step_s"] > 0 for c in cases.values())
    assert data["scaling"]["fit"]["iterative"]["step_s"]["points"] == 4
    anchors = data["scaling"]["anchors"]  # the plain-elasticity anchor beside every case
    assert sorted(anchors) == ["plain-gamg/np1/n2", "plain-gamg/np1/n3", "plain-gamg/np2/n2", "plain-gamg/np2/n3"]
    assert all(c["status"] == "ok" and c["iterations"] > 0 for c in anchors.values())
    assert data["scaling"]["blas"]["kind"] in blas.KINDS and all(c["blas"] for c in cases.values())
    md = (tmp_path / "scaling.md").read_text()
    assert "| 3 | 192 | iterative | 2 | 1 |" in md and "Cost model" in md and "| 3 | 192 | 2 | gamg |" in md
    # in pieces: a second call runs only what is missing, and a budget skips with its reason
    res = run_cli(["bench", "--scaling", "--sizes", "2", "3", "--solvers", "iterative", "mumps", "--nproc", "1",
                   "--steps", "1", "--budget-s", "1e-9", "--output", str(tmp_path), "--allow-reference-blas"])
    assert res.returncode == 0, res.stderr
    assert "iterative/np1/n3: already measured" in res.stdout
    cases = json.loads((tmp_path / "bench.json").read_text())["scaling"]["cases"]
    assert cases["mumps/np1/n2"]["status"] == "ok"  # nothing smaller to predict from: measured
    assert cases["mumps/np1/n3"]["status"] == "skipped" and "budget" in cases["mumps/np1/n3"]["reason"]
    assert len(cases) == 6
    for opt, value in (("--sizes", "0"), ("--nproc", "0"), ("--budget-s", "-1")):
        bad = run_cli(["bench", "--scaling", opt, value, "--output", str(tmp_path)])
        assert bad.returncode == 2 and bad.stderr.count("\n") == 1  # one line: the option, its value, what is allowed
        assert bad.stderr.startswith(f"error: {opt} {value}") and "must be" in bad.stderr


def test_anchor_table_reads_every_case_as_a_ratio_to_the_plain_solve():
    """Step over one plain solve, Krylov iterations and peak memory over the plain solve's; direct: level 0 over
    the plain factorization."""
    n, dofs = 20, scaling.dofs_of(20)
    cases = {scaling.key("iterative", 1, n): _case("iterative", 1, n, step_s=0.3, krylov_per_solve=30.0,
                                                    peak_mib_max=400.0, peak_mib_sum=400.0, cli_peak_mib_max=500.0,
                                                    cli_step_s=0.35),
             scaling.key("mumps", 1, n): _case("mumps", 1, n, step_s=0.05, level0_s=12.0, peak_mib_max=600.0,
                                               peak_mib_sum=600.0, level0_setups=2)}
    plain = {"n": n, "nproc": 1, "dofs": dofs, "status": "ok", "setup_s": 0.5, "solve_s": 0.25, "iterations": 20,
             "peak_mib_max": 200.0, "peak_mib_sum": 200.0}
    anchors = {scaling.anchor_key("gamg", 1, n): dict(plain, solver="gamg"),
               scaling.anchor_key("mumps", 1, n): dict(plain, solver="mumps", setup_s=4.0, solve_s=0.01, iterations=1),
               scaling.anchor_key("gamg", 2, n): dict(plain, solver="gamg", nproc=2, status="failed", reason="x")}
    text = "\n".join(scaling.anchor_table({"cases": cases, "anchors": anchors}))
    per_dof = f"{400 * 2 ** 20 / dofs:,.0f}"
    assert f"| iterative | 1.20 | - | - | 1.50 | 2.00 | {per_dof} | 2.50 | 1.40 |" in text  # the CLI's: 500 / 200
    assert "| mumps | 5.00 | 3.00 | 1.50 | - | 3.00 |" in text  # level 0 holds two factorizations
    assert "| 20 | 27,783 | 2 | gamg | failed: x |" in text


def test_the_docs_page_carries_the_generated_blocks_markers():
    """`bench --scaling` rewrites the block between the markers; a marker that drifts from the code's silently stops
    the rewrite (it had: the page said '.venv/bin/python -m studies ...')."""
    from studies import REPO
    from studies.scaling import README_BEGIN, README_END

    text = (REPO / "docs" / "benchmarks" / "scaling.md").read_text()
    assert README_BEGIN in text and README_END in text
