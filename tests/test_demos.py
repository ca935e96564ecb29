"""The demos (demos/*.py, jupytext percent scripts) run as a user runs them, each in its own process, in under a
minute, and write their charts (as the dolfinx demos do in CI)."""

import importlib.util
import os
import subprocess
import sys

import pytest
from conftest import ROOT, mpi_env

DEMOS = sorted((ROOT / "demos").glob("*.py"))
CHARTS = {"example1": ["example1_series.png", "example1_damage.png"], "parameter_study": ["parameter_study.png"],
          "own_scene": ["plate_with_hole.msh", "plate_with_hole/solution.xdmf"], "read_results": ["read_results.png"]}


def test_every_demo_is_listed():
    assert {d.stem for d in DEMOS} == set(CHARTS)


@pytest.mark.serial
@pytest.mark.skipif(importlib.util.find_spec("matplotlib") is None, reason="the demos draw with matplotlib (PLOTS=1)")
@pytest.mark.parametrize("demo", DEMOS, ids=lambda p: p.stem)
def test_demo_runs(demo, tmp_path):
    env = dict(mpi_env(), DEMO_OUTPUT=str(tmp_path), PYTHONPATH=str(ROOT), MPLBACKEND="Agg")
    res = subprocess.run([sys.executable, str(demo)], cwd=tmp_path, env=env, capture_output=True, text=True, timeout=120)
    assert res.returncode == 0, res.stderr[-3000:]
    for name in CHARTS[demo.stem]:
        assert (tmp_path / name).is_file(), name
    assert "Traceback" not in res.stderr


def test_demos_are_jupytext_percent_scripts():
    """Each opens as a notebook: the jupytext header and markdown cells beside the code."""
    for demo in DEMOS:
        text = demo.read_text()
        assert "format_name: percent" in text and "# %% [markdown]" in text, demo.name
        assert os.access(demo, os.R_OK)
