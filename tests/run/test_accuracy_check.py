"""solver/run/accuracy/check.py: the ``--set`` overrides a tolerance decides itself, and the command line's refusals."""

import pytest
from conftest import run_cli as cli

from solver.run.accuracy.check import contradicting


def test_settings_it_chooses_contradict_it():
    assert contradicting(["mesh.nx=8", "time.T=2", "time.k=0.1", "material.E=3", "discretization.zeta_degree=1"]) == [
        "mesh.nx=8", "time.k=0.1", "discretization.zeta_degree=1"]
    assert contradicting([" time.order = 2", "mesh.nz=3", "discretization.u_degree=2"]) == [
        " time.order = 2", "mesh.nz=3", "discretization.u_degree=2"]


@pytest.mark.serial
@pytest.mark.parametrize("args,key", [(["--tolerance", "0"], "tolerance"), (["--tolerance", "nan"], "tolerance"),
                                      (["--tolerance", "2"], "tolerance"), (["--tolerance", "abc"], "--tolerance"),
                                      (["--tolerance", "1e-2", "--set", "mesh.nx=8"], "mesh.nx=8"),
                                      (["--tolerance", "1e-2", "--set", "time.k=0.05"], "time.k=0.05")])
def test_bad_tolerance_on_the_command_line_is_one_line_exit_2(tmp_path, args, key):
    out = tmp_path / "o"
    res = cli(["run", "configs/example1.toml", *args, "--output", str(out), "--no-progress"])
    assert res.returncode == 2, res.stderr
    assert res.stderr.count("\n") == 1 and res.stderr.startswith("error: ") and key in res.stderr, res.stderr
    assert "Traceback" not in res.stderr and not out.exists()
