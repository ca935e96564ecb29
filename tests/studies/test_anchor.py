"""studies/anchor.py: the plain-elasticity anchor of bench --scaling (plain dolfinx, no solver module)."""

import ast
from pathlib import Path

import pytest

from studies import anchor


def test_anchor_solves_agree_between_gamg_and_mumps_and_use_the_scene_material():
    it, direct = anchor.run_case(4, "gamg"), anchor.run_case(4, "mumps")
    assert it["dofs"] == direct["dofs"] == 3 * 5 ** 3
    assert 0 < it["iterations"] < 50 and direct["iterations"] == 1
    assert it["norm_u"] == pytest.approx(direct["norm_u"], rel=1e-6) and direct["norm_u"] > 0
    assert it["peak_mib_sum"] >= it["peak_mib_max"] > 0 and it["solve_s"] > 0
    text = (Path(__file__).parents[2] / "configs" / "example1_3d.toml").read_text()
    assert f"E = {anchor.E}" in text and f"nu = {anchor.NU}" in text
    assert "traction = [" + ", ".join(str(v) for v in anchor.TRACTION) + "]" in text


def test_anchor_imports_none_of_the_solver():
    tree = ast.parse(Path(anchor.__file__).read_text())
    names = {a.name for n in ast.walk(tree) if isinstance(n, ast.Import) for a in n.names}
    names |= {n.module for n in ast.walk(tree) if isinstance(n, ast.ImportFrom) and n.module}
    assert not any(n == "solver" or n.startswith("solver.") for n in names)
