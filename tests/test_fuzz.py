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
