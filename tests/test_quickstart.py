"""docs/quickstart.md as a new user follows it, right after `make demo`: every command of the page, in its order,
succeeds, and the run ends with the figures the page shows."""

import re
import shlex
import subprocess
import sys

import pytest
from conftest import ROOT, mpi_env

pytestmark = [pytest.mark.serial, pytest.mark.slow]  # starts its own processes


def _commands(text: str) -> list[list[str]]:
    """The commands of the page's ```bash blocks, comments dropped, the venv's Python as this test's."""
    out = []
    for block in re.findall(r"```bash\n(.*?)```", text, flags=re.S):
        for line in block.splitlines():
            words = shlex.split(line, comments=True)
            if words:
                assert words[0] == ".venv/bin/python", line
                out.append([sys.executable, *words[1:]])
    return out


def _demo() -> list[str]:
    """The command `make demo` runs."""
    recipe = re.search(r"^demo:.*\n\t(.*)$", (ROOT / "Makefile").read_text(), flags=re.M).group(1)
    words = shlex.split(recipe)
    assert words[0] == "$(PY)", recipe
    return [sys.executable, *words[1:]]


def test_the_quickstart_runs_after_make_demo(tmp_path):
    page = (ROOT / "docs" / "quickstart.md").read_text()
    (tmp_path / "configs").symlink_to(ROOT / "configs")
    env = {**mpi_env(), "PYTHONPATH": str(ROOT)}
    demo = subprocess.run(_demo(), cwd=tmp_path, env=env, capture_output=True, text=True, timeout=600)
    assert demo.returncode == 0, demo.stderr[-2000:]
    commands = _commands(page)
    assert len(commands) >= 2
    for i, cmd in enumerate(commands):
        res = subprocess.run(cmd, cwd=tmp_path, env=env, capture_output=True, text=True, timeout=600)
        assert res.returncode == 0, (cmd, res.stderr[-2000:])
        if i == 0:  # the run: its closing lines as the page prints them, but for the seconds
            shown = re.search(r"```\n(done in .*?)\n```", page, flags=re.S).group(1).splitlines()
            said = [ln for ln in res.stderr.splitlines() if ln.startswith(("done in", "results in"))]
            drop = re.compile(r"done in [0-9.]+ s")
            assert [drop.sub("done", s) for s in said] == [drop.sub("done", s) for s in shown], res.stderr[-1000:]
    listed = set(re.findall(r"^- `([\w.]+)`", page, flags=re.M))  # "What it wrote"
    written = {p.name for p in (tmp_path / "results" / "quickstart").iterdir()}
    assert listed and listed <= written, (listed, written)
