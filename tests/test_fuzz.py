"""Fuzzed scene loader and command line (issue 32): generated scenes, --set overrides and CLI arguments give a
result or exit 2 with one line, never a traceback and never a file written on failure (tests/fuzzing.py). A
bounded number of examples here; scripts/fuzz_campaign.py runs a longer campaign."""

from __future__ import annotations

import os
import tempfile
from pathlib import Path

import pytest
from fuzzing import OVERRIDES, TEXT, call_cli, check_one_line, scene_property, scenes
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

pytestmark = pytest.mark.serial  # the CLI in this process reads and writes files on rank 0's view

EXAMPLES = int(os.environ.get("FUZZ_EXAMPLES", "60"))
SETTINGS = settings(max_examples=EXAMPLES, deadline=None, derandomize=True, database=None,
                    suppress_health_check=list(HealthCheck))


@SETTINGS
@given(doc=scenes(), overrides=OVERRIDES)
def test_fuzzed_scenes_and_overrides(doc, overrides):
    with tempfile.TemporaryDirectory() as tmp:
        scene_property(doc, overrides, Path(tmp), run=False)


ARGS = st.lists(st.one_of(st.sampled_from(["run", "check", "plot", "paraview", "--set", "--output", "-o", "",
                                           "--tolerance", "--restart", "--overwrite", "--no-progress", "--help-me",
                                           "configs/example1.toml", "nonexistent.toml", "1e-9", "nan", "-1", "0",
                                           "mesh.nx=4", "mesh.nx", "=", "--times", "--field", "/"]), TEXT),
                max_size=6)


@SETTINGS
@given(argv=ARGS)
def test_fuzzed_command_lines(argv):
    """Any command line: exit 0 or 2 with one error line (argparse's usage line allowed), never a traceback.
    Runs are kept out (a valid one would compute): only check, plot and paraview, and run's refusals."""
    if argv[:1] == ["run"] and "configs/example1.toml" in argv and "--tolerance" not in argv:
        argv = [*argv, "--set", "nosuch.key=1"]  # refused before computing: tests the order of the checks
    with tempfile.TemporaryDirectory() as tmp:
        cwd = os.getcwd()
        try:
            argv = [a if a != "/" else tmp for a in argv]
            code, _, err = call_cli(argv)
        finally:
            os.chdir(cwd)
    check_one_line(code, err, f"solver {argv!r}")


def test_a_scene_path_too_long_is_one_line():
    """Found by the campaign: a 300-character file name was an OSError traceback (File name too long)."""
    code, _, err = call_cli(["check", "a" * 300])
    check_one_line(code, err, "check aaa...")
    assert code == 2 and "cannot read the scene file (File name too long)" in err


# ----------------------------------------------------------------------------- result directories (plot, paraview)

RESULT_EXAMPLES = int(os.environ.get("FUZZ_RESULT_EXAMPLES", "20"))


@pytest.fixture(scope="module")
def results_base(tmp_path_factory):
    """A tiny real results directory (example 1, 4 x 4 mesh, three levels) that every example damages a copy of."""
    from fuzzing_results import make_base

    return make_base(tmp_path_factory.mktemp("fuzz_results"))


@pytest.fixture(scope="module")
def plot_worker():
    """A dolfinx-free process that runs ``solver plot`` (VTK and dolfinx's C++ do not mix in one process)."""
    pytest.importorskip("pyvista", reason="the plotting extra is not installed (make install PLOTS=0)")
    from fuzzing_results import PlotWorker

    worker = PlotWorker()
    yield worker
    worker.close()


def test_fuzzed_result_directories_for_plot(results_base, plot_worker):
    """Truncated .h5, missing datasets and files, datasets of another shape, broken XDMF, damaged CSVs: plot draws
    or exits 2 with one line naming the file; no traceback, nothing written on a refusal."""
    from fuzzing_results import DAMAGE_LISTS, plot_command, results_property

    @settings(SETTINGS, max_examples=RESULT_EXAMPLES)
    @given(damages=DAMAGE_LISTS)
    def one(damages):
        with tempfile.TemporaryDirectory() as tmp:
            results_property(results_base, damages, Path(tmp), plot_command(plot_worker))

    one()


# what each damage is refused for (None: the picture is drawn), the same for plot and paraview
HAND_PICKED = [
    ([("truncate", "fields/levels_000001.h5", 0.5)], "levels_000001.h5: not a readable HDF5 file (Unable to open"),
    ([("xml", 0, 0, 0)], "fields/missing.h5: does not exist (named by solution.xdmf)"),
    ([("xml_cut", 0.5)], "solution.xdmf: not readable XML"),
    ([("h5", "fields/levels_000001.h5", 0, "fewer_rows")], "levels_000001.h5: /0000/damage: float64 of shape (24,), "
                                                           "solution.xdmf says numbers of shape (25,)"),
    ([("h5", "fields/mesh.h5", 1, "drop")], "mesh.h5: has no dataset /topology (topology, named by solution.xdmf)"),
    ([("empty_directory",)], "no solution.xdmf"),
    # found by the campaign: the last level's geometry naming a missing dataset (pvbatch aborted with SIGABRT)
    ([("xml", 1, 85, 33)], "mesh.h5: has no dataset /0009/displacement (geometry at level 2, named by solution.xdmf)"),
]
PLOT_ONLY = [
    ([("csv", "timeseries.csv", 0, 6, "drop_column")], "timeseries.csv: no column contact_force"),
    ([("csv", "contact.csv", 2, 3, "abc")], "contact.csv: line 4: s = 'abc' is not a number"),
    ([("csv", "timeseries.csv", 0, 0, "empty")], "timeseries.csv: no column t, contact_force, zeta_min, strain_norm "
                                                 "(it has no header line)"),
]


@pytest.mark.parametrize(("damages", "message"), HAND_PICKED + PLOT_ONLY)
def test_damaged_result_directories_for_plot(results_base, plot_worker, tmp_path, damages, message):
    """Each of the issue's damages (fails on the original code: a KeyError, OSError or ParseError traceback)."""
    from fuzzing_results import plot_command, results_property

    assert results_property(results_base, damages, tmp_path, lambda d: _expect(plot_command(plot_worker), d,
                                                                             message)) == "refused"


def _expect(command, directory, message):
    code, out, err = command(directory)
    assert code == 2 and message in err, err
    return code, out, err


@pytest.fixture(scope="module")
def paraview():
    import solver.post.paraview as spv

    if not spv.available():
        pytest.skip("ParaView (pvbatch) is not installed: apt-get install paraview")
    problem = spv.python_problem()
    if problem:
        pytest.skip(problem.removeprefix("error: "))


@pytest.mark.parametrize(("damages", "message"), HAND_PICKED)
def test_damaged_result_directories_for_paraview(results_base, paraview, tmp_path, damages, message):
    """The same damages handed to paraview: refused in one line naming the file before ParaView starts (before,
    pvbatch aborted with SIGABRT after ~200 lines of VTK errors, or drew the last level, skipped the damaged one
    silently and exited 0)."""
    from fuzzing_results import paraview_command, results_property

    assert results_property(results_base, damages, tmp_path,
                            lambda d: _expect(paraview_command, d, message)) == "refused"


@pytest.mark.slow
def test_paraview_draws_a_directory_whose_csv_is_damaged(results_base, paraview, tmp_path):
    """ParaView reads only the XDMF series: a damaged CSV beside it is no reason to refuse (one PNG written)."""
    from fuzzing_results import paraview_command, results_property

    damages = [("csv", "timeseries.csv", 0, 6, "drop_column")]
    assert results_property(results_base, damages, tmp_path, paraview_command) == "ok"
    assert (tmp_path / "r" / "paraview_von_mises_elastic.png").is_file()


def test_plot_draws_fields_holding_nan_quietly(results_base, plot_worker, tmp_path):
    """NaN in a level's displacement and von Mises (a diverged or damaged write): the pictures are drawn, the warp
    and the colour range from the finite values, and nothing on stderr (no numpy warning)."""
    from fuzzing_results import plot_command, results_property

    damages = [("h5", "fields/levels_000000.h5", 1, "nan"), ("h5", "fields/levels_000000.h5", 2, "nan")]  # t = 0
    seen = {}

    def command(directory):
        seen["result"] = plot_command(plot_worker)(directory)
        return seen["result"]

    assert results_property(results_base, damages, tmp_path, command) == "ok"
    code, out, err = seen["result"]
    assert err == "" and "von_mises_final.png" in out and "damage_final.png" in out
