"""Property-based fuzzing of the scene loader and the command line (issue 32), shared by
tests/test_fuzz.py (a bounded number of examples in ``make test``) and scripts/fuzz_campaign.py (a longer
campaign that reports how many inputs it tried and what it found).

Scenes are made from the schema itself: the resolved default scene (every section's keys and values) is
mutated -- values replaced by wrong types, out-of-range and non-finite numbers, huge and empty tables, unicode,
deep nesting; keys dropped and unknown keys added -- and written as TOML, with ``--set`` overrides drawn the
same way. The property: ``load`` returns a Config or raises a ConfigError whose message is one line; on small
valid scenes ``solver check`` (in this process) exits 0, otherwise 2 with one line, never a traceback.
"""

from __future__ import annotations

import contextlib
import io
import math
import os
import sys
import tempfile
from pathlib import Path

import tomlkit
from hypothesis import strategies as st

from solver.config import from_dict, to_dict

DEFAULT = to_dict(from_dict({}))
SECTIONS = list(DEFAULT)


def _paths(node: dict, prefix: tuple = ()) -> list[tuple]:
    out = []
    for key, value in node.items():
        out.append((*prefix, key))
        if isinstance(value, dict):
            out += _paths(value, (*prefix, key))
    return out


PATHS = _paths(DEFAULT)
NUMBERS = st.sampled_from([0, -1, 1, 2, 3, 7, 10**30, -(2**63), 2**64, 0.0, -0.5, 0.5, 1.5, 1e-300, 1e300,
                           math.inf, -math.inf, math.nan])
TEXT = st.one_of(st.sampled_from(["", "left", "bottom", "clamped", "gmsh", "box", "none", "ζ", "\u202e",
                                  "a" * 300, "../../etc/passwd", "nan"]),
                 st.text(max_size=12))
LEAF = st.one_of(NUMBERS, TEXT, st.booleans(), st.lists(NUMBERS, max_size=4), st.lists(TEXT, max_size=3),
                 st.just([[0.0, 0.0], [1.0, 1.0]]), st.just([]), st.just({}))


def _deep(depth: int) -> dict:
    node: dict = {"x": 1}
    for _ in range(depth):
        node = {"t": node}
    return node


VALUES = st.one_of(LEAF, st.dictionaries(TEXT, LEAF, max_size=3),
                   st.integers(1, 60).map(_deep),
                   st.integers(1000, 3000).map(lambda n: {f"k{i}": i for i in range(n)}))


@st.composite
def scenes(draw) -> dict:
    """A scene document: the defaults, some sections left out, some values replaced, dropped or added."""
    keep = draw(st.lists(st.sampled_from(SECTIONS), min_size=1, max_size=len(SECTIONS), unique=True))
    doc = {s: _copy(DEFAULT[s]) for s in keep}
    if draw(st.booleans()):  # small and short (before the mutations): what check and run try
        if isinstance(doc.get("mesh"), dict) and doc["mesh"].get("kind") == "rectangle":
            doc["mesh"]["nx"], doc["mesh"]["ny"] = 4, 4
        doc.setdefault("time", _copy(DEFAULT["time"]))["k"] = draw(st.sampled_from([0.25, 0.5, 1.0]))
    for _ in range(draw(st.integers(0, 4))):
        path = draw(st.sampled_from(PATHS))
        action = draw(st.sampled_from(["replace", "drop", "unknown"]))
        node = doc
        for part in path[:-1]:
            node = node.get(part) if isinstance(node, dict) else None
        if not isinstance(node, dict):
            continue
        if action == "replace":
            node[path[-1]] = draw(VALUES)
        elif action == "drop":
            node.pop(path[-1], None)
        else:
            node[draw(TEXT) or "x"] = draw(VALUES)
    return doc


def _copy(v):
    if isinstance(v, dict):
        return {k: _copy(x) for k, x in v.items()}
    if isinstance(v, list):
        return [_copy(x) for x in v]
    return v


OVERRIDE_VALUES = st.one_of(st.sampled_from(["1", "-1", "0", "nan", "inf", "1e400", "[]", "{}", "[1, 2", "true",
                                             '"ζ"', "'", "=", "", "[[0.0, 0.0], [1.0, 1.0]]", "{a = 1}"]),
                            st.text(max_size=8).filter(lambda s: "\x00" not in s))
OVERRIDE_KEYS = st.one_of(st.sampled_from([".".join(p) for p in PATHS]),
                          st.sampled_from(["", ".", "mesh", "mesh.", ".nx", "a.b.c.d", "mesh.nx.y", "ζ.k"]),
                          st.text(max_size=10))
OVERRIDES = st.lists(st.builds(lambda k, v: f"{k}={v}", OVERRIDE_KEYS, OVERRIDE_VALUES) | TEXT, max_size=3)


def write(doc: dict, path: Path) -> bool:
    """Write doc as TOML; False if TOML cannot hold it (then it is no scene a user could write)."""
    try:
        path.write_text(tomlkit.dumps(doc))
    except (ValueError, TypeError, RecursionError, UnicodeEncodeError):
        return False
    return True


def small(cfg) -> bool:
    """A scene cheap enough to check (and run) in the fuzz test: a small built-in mesh and few steps."""
    m = cfg.mesh
    cells = (m.nx * m.ny * 2) if m.kind == "rectangle" else (m.nx * m.ny * m.nz * 6 if m.kind == "box" else 10**9)
    return cells <= 2000 and cfg.time.steps <= 10**5


def call_cli(argv: list[str]) -> tuple[int, str, str]:
    """``solver ARGV`` in this process: (exit code, stdout, stderr). argparse's exits count as exit codes. What
    child processes (ParaView) and native code write on file descriptors 1 and 2 counts too: the user sees it."""
    from solver.cli import main

    out, err = io.StringIO(), io.StringIO()
    with _native_output() as native, contextlib.redirect_stdout(out), contextlib.redirect_stderr(err):
        try:
            code = main(argv)
        except SystemExit as exc:
            code = exc.code if isinstance(exc.code, int) else 2
        except Exception as exc:  # what a user would see as a traceback
            raise Defect(f"solver {argv!r}: traceback: {type(exc).__name__}: {exc}"[:2000]) from exc
    return code, out.getvalue() + native["out"], err.getvalue() + native["err"]


@contextlib.contextmanager
def _native_output():
    """File descriptors 1 and 2 sent to temporary files for the block; their text in the dict yielded, after it."""
    sys.stdout.flush()
    sys.stderr.flush()
    saved = [os.dup(1), os.dup(2)]
    files = [tempfile.TemporaryFile(), tempfile.TemporaryFile()]
    got: dict[str, str] = {}
    try:
        os.dup2(files[0].fileno(), 1)
        os.dup2(files[1].fileno(), 2)
        yield got
    finally:
        for fd, old in zip((1, 2), saved):
            os.dup2(old, fd)
            os.close(old)
        for key, f in zip(("out", "err"), files):
            f.seek(0)
            got[key] = f.read().decode(errors="replace")
            f.close()


class Defect(AssertionError):
    """What the fuzzer looks for: a traceback, a message that is not one line, a wrong exit code, a file left."""


def check_one_line(code: int, err: str, what: str) -> None:
    """Exit 0, or exit 2 with one error line (argparse's own refusals: its usage lines and one error line)."""
    if code not in (0, 2):
        raise Defect(f"{what}: exit {code}: {err[-2000:]}")
    if "Traceback" in err:
        raise Defect(f"{what}: traceback: {err[-2000:]}")
    if code == 2:
        # split at newlines only (splitlines also splits at \x85, which a terminal shows in the line)
        lines = [ln for ln in err.split("\n") if ln.strip() and not ln.startswith(("usage:", " "))]
        if len(lines) != 1 or "error" not in lines[0]:
            raise Defect(f"{what}: not one error line: {err!r}")


def scene_property(doc: dict, overrides: list[str], tmp: Path, run: bool = False) -> str:
    """The property for one scene and its overrides: returns 'unwritable', 'refused', 'ok' (valid; with ``run``
    and at most 20 steps: 'ran', or 'run_failed' for a solve that failed in one line); raises Defect."""
    from solver.config import load
    from solver.errors import ConfigError

    scene = tmp / "scene.toml"
    if not write(doc, scene):
        return "unwritable"
    what = f"scene {doc!r:.300} --set {overrides!r}"
    try:
        cfg = load(scene, overrides)
    except ConfigError as exc:
        if "\n" in str(exc) or not str(exc):
            raise Defect(f"{what}: ConfigError not one line: {exc!r}") from None
        return "refused"
    except RecursionError as exc:
        raise Defect(f"{what}: {exc!r}") from None
    except Exception as exc:  # any other exception is a traceback for the user
        raise Defect(f"{what}: {type(exc).__name__}: {exc}") from exc
    if not small(cfg):
        return "ok"
    argv = ["check", str(scene), *(a for o in overrides for a in ("--set", o))]
    code, _, err = call_cli(argv)
    check_one_line(code, err, what + " (check)")
    if run and code == 0 and cfg.time.steps <= 20:
        out = tmp / "out"
        code, _, err = call_cli(["run", str(scene), *argv[2:], "--output", str(out), "--no-progress"])
        if code == 1 and err.startswith("failed:") and err.count("\n") == 1:
            return "run_failed"  # a scene that is valid but whose solve fails: exit 1, one line, results kept
        check_one_line(code, err, what + " (run)")
        if code == 2 and out.exists():
            raise Defect(f"{what} (run): refused but wrote {sorted(p.name for p in out.iterdir())}")
        if code == 0:
            if not (out / "timeseries.csv").is_file():
                raise Defect(f"{what} (run): exit 0 but no timeseries.csv in {out}")
            return "ran"
    return "ok" if code == 0 else "refused"
