"""Property-based fuzzing of the result directories handed to ``solver plot`` and ``solver paraview`` (issue 32),
shared by tests/test_fuzz.py (a bounded number of examples) and scripts/fuzz_campaign.py (a longer campaign).

A small real results directory (:func:`make_base`: example 1 on a 4 x 4 mesh, times 0, 0.5, 1) is copied and
damaged the ways files are damaged: truncated at a random byte, deleted, replaced by garbage or by a directory;
an ``.h5`` dataset removed, of another shape or type, or NaN; the XDMF naming a missing file or dataset, with
garbage dimensions or times, cut or broken XML; a CSV without a column, with a value that is no number, a short
row, or empty; the whole directory emptied. The property: the command exits 0, or 2 with one line on stderr
that names a file of the directory; never a traceback, never another exit code, and on a refusal no file written
or changed (on success only new PNGs).

``solver plot`` cannot run in a process that has loaded dolfinx (VTK and dolfinx's C++ do not mix: a segfault
in the render), so plots run in a worker process (:class:`PlotWorker`) that never imports dolfinx; what is written
on file descriptor 2 (VTK's own messages) counts as what the user sees (fuzzing.call_cli).
"""

from __future__ import annotations

import hashlib
import json
import os
import re
import shutil
import subprocess
import sys
from pathlib import Path

import h5py
import numpy as np
from fuzzing import Defect, check_one_line
from hypothesis import strategies as st

ROOT = Path(__file__).resolve().parents[1]
BASE_FILES = ("solution.xdmf", "timeseries.csv", "contact.csv", "config.toml", "checkpoint.h5", "fields/mesh.h5",
              "fields/levels_000000.h5", "fields/levels_000001.h5", "contact.xdmf", "fields/contact_mesh.h5",
              "fields/contact_levels_000000.h5", "fields/contact_levels_000001.h5")
H5_FILES = ("fields/mesh.h5", "fields/levels_000000.h5", "fields/levels_000001.h5")
CSV_FILES = ("timeseries.csv", "contact.csv")


def make_base(directory: Path) -> Path:
    """The results directory every example damages a copy of (a run in a subprocess: no dolfinx here)."""
    out = directory / "base"
    cmd = [sys.executable, "-m", "solver", "run", "configs/example1.toml", "--set", "mesh.nx=4", "--set", "mesh.ny=4",
           "--set", "time.k=0.5", "--no-progress", "--output", str(out)]
    res = subprocess.run(cmd, cwd=ROOT, capture_output=True, text=True, timeout=600)
    assert res.returncode == 0, res.stderr[-2000:]
    assert {str(p.relative_to(out)) for p in out.rglob("*") if p.is_file()} == set(BASE_FILES)
    return out


# XDMF edits: (regex, replacements); the n-th match (modulo their number) is replaced
XML_EDITS = (
    (r"fields/[a-z_0-9]+\.h5(?=:)", ("fields/missing.h5", "fields", "mesh.h5", "../base/fields/mesh.h5", "")),
    (r"(?<=\.h5:)/[^<]+", ("/nosuch", "/", "", "/0009/displacement", "/topology")),
    (r'(?<=Dimensions=")[^"]*', ("abc", "", "1 2 3", "25 2", "32", "-1", "1e3")),
    (r'(?<=Value=")[^"]*', ("abc", "", "nan", "inf", "1e999")),
    (r'(?<=Name=")[^"]*', ("", "ζ", "x y")),
    (r"<Time[^>]*/>", ("",)),
    (r"<DataItem", ("<DataItemX", "<")),
    (r"</Grid>", ("", "</Grid></Grid>")),
    (r'NumberType="\w+"', ('NumberType="Char"',)),
)
DAMAGES = st.one_of(
    st.tuples(st.just("truncate"), st.sampled_from(BASE_FILES), st.floats(0, 1)),
    st.tuples(st.just("delete"), st.sampled_from(BASE_FILES)),
    st.tuples(st.just("garbage"), st.sampled_from(BASE_FILES), st.binary(max_size=64)),
    st.tuples(st.just("directory"), st.sampled_from(BASE_FILES)),
    st.tuples(st.just("h5"), st.sampled_from(H5_FILES), st.integers(0, 99),
              st.sampled_from(["drop", "fewer_rows", "more_columns", "scalar", "strings", "nan", "integers"])),
    st.tuples(st.just("xml"), st.integers(0, len(XML_EDITS) - 1), st.integers(0, 99), st.integers(0, 99)),
    st.tuples(st.just("xml_cut"), st.floats(0, 1)),
    st.tuples(st.just("csv"), st.sampled_from(CSV_FILES), st.integers(0, 99), st.integers(0, 99),
              st.sampled_from(["drop_column", "abc", "", "nan", "1e999", "short_row", "long_row", "header_only",
                               "empty", "latin1"])),
    st.tuples(st.just("empty_directory")),
)
DAMAGE_LISTS = st.lists(DAMAGES, min_size=1, max_size=3)


def damage(directory: Path, how: tuple) -> None:
    """Apply one damage (a tuple drawn from DAMAGES) to a copy of the base directory."""
    kind, *arg = how
    if kind == "empty_directory":
        for p in list(directory.iterdir()):
            shutil.rmtree(p) if p.is_dir() else p.unlink()
        return
    if kind in ("xml", "xml_cut"):
        return _damage_xml(directory / "solution.xdmf", kind, arg)
    path = directory / arg[0]
    if not path.is_file():  # an earlier damage removed it
        return
    if kind == "truncate":
        os.truncate(path, int(path.stat().st_size * arg[1]))
    elif kind == "delete":
        path.unlink()
    elif kind == "garbage":
        path.write_bytes(arg[1])
    elif kind == "directory":
        path.unlink()
        path.mkdir()
    elif kind == "h5":
        _damage_h5(path, *arg[1:])
    else:
        _damage_csv(path, *arg[1:])


def _damage_xml(path: Path, kind: str, arg: list) -> None:
    if not path.is_file():
        return
    text = path.read_text(errors="replace")
    if kind == "xml_cut":
        path.write_text(text[: int(len(text) * arg[0])])
        return
    pattern, replacements = XML_EDITS[arg[0]]
    matches = list(re.finditer(pattern, text))
    if matches:
        m = matches[arg[1] % len(matches)]
        path.write_text(text[: m.start()] + replacements[arg[2] % len(replacements)] + text[m.end():])


def _damage_h5(path: Path, index: int, how: str) -> None:
    try:
        f = h5py.File(path, "r+")
    except OSError:  # damaged already
        return
    with f:
        names: list[str] = []
        f.visititems(lambda name, obj: names.append(name) if isinstance(obj, h5py.Dataset) else None)
        if not names:
            return
        name = names[index % len(names)]
        data = f[name][...]
        del f[name]
        rows = data.shape[0] if data.ndim else 1  # an earlier damage may have left a scalar or strings
        if how == "fewer_rows":
            f[name] = data[:-1] if data.ndim else np.zeros(0)
        elif how == "more_columns":
            f[name] = np.zeros((rows, data.reshape(rows, -1).shape[1] + 1))
        elif how == "scalar":
            f[name] = 1.0
        elif how == "strings":
            f[name] = np.array([b"x"] * max(rows, 1))
        elif how == "nan":
            f[name] = np.full(data.shape, np.nan)
        elif how == "integers":
            f[name] = data.astype(np.int64) if data.dtype.kind in "iuf" else np.zeros(data.shape, np.int64)


def _damage_csv(path: Path, row: int, column: int, how: str) -> None:
    lines = path.read_text(errors="replace").splitlines()
    if not lines:  # emptied by an earlier damage
        return
    header = lines[0].split(",")
    body = lines[1:]
    c = column % len(header)
    r = row % len(body) if body else 0
    if how == "drop_column":
        lines = [",".join(v for j, v in enumerate(ln.split(",")) if j != c) for ln in lines]
    elif how in ("short_row", "long_row") and body:
        cells = body[r].split(",")
        body[r] = ",".join(cells[:-1] if how == "short_row" else [*cells, "1"])
        lines = [lines[0], *body]
    elif how == "header_only":
        lines = lines[:1]
    elif how == "empty":
        lines = []
    elif how == "latin1":
        path.write_bytes(("\n".join(lines) + "\nζ\xe9").encode("latin-1", errors="replace") + b"\xe9\xff\n")
        return
    elif body:
        cells = body[r].split(",")
        cells[c] = how
        body[r] = ",".join(cells)
        lines = [lines[0], *body]
    path.write_text("\n".join(lines) + ("\n" if lines else ""))


def snapshot(directory: Path) -> dict[str, str]:
    """Every entry under directory: files by content hash, directories as 'dir'."""
    out = {}
    for p in sorted(directory.rglob("*")):
        out[str(p.relative_to(directory))] = "dir" if p.is_dir() else hashlib.sha1(p.read_bytes()).hexdigest()
    return out


def results_property(base: Path, damages: list[tuple], tmp: Path, command) -> str:
    """Damage a copy of base, hand it to ``command(directory) -> (code, stdout, stderr)``; returns 'ok' or
    'refused', raises Defect. On exit 2 the one line names a file of the directory and nothing was written."""
    directory = tmp / "r"
    shutil.copytree(base, directory)
    for how in damages:
        damage(directory, how)
    before = snapshot(directory)
    code, _, err = command(directory)
    what = f"damaged results {damages!r}"
    check_one_line(code, err, what)
    after = snapshot(directory)
    if code == 2:
        line = [ln for ln in err.split("\n") if ln.strip()][-1]
        if str(directory) not in line:
            raise Defect(f"{what}: the error names no file of the directory: {line!r}")
        if after != before:
            raise Defect(f"{what}: refused but wrote {sorted(set(after.items()) ^ set(before.items()))}")
        return "refused"
    changed = sorted(k for k in before if after.get(k) != before[k])
    new = sorted(k for k in after if k not in before and not k.endswith(".png"))
    if changed or new:
        raise Defect(f"{what}: changed {changed}, wrote {new}")
    return "ok"


WORKER = r"""
import json, os, sys
sys.path[:0] = [sys.argv[1], os.path.join(sys.argv[1], "tests")]
from fuzzing import Defect, call_cli
out = os.fdopen(os.dup(1), "w")  # the replies (call_cli catches what is written on descriptors 1 and 2)
for line in sys.stdin:
    try:
        code, o, e = call_cli(json.loads(line))
        reply = {"code": code, "out": o, "err": e}
    except Defect as exc:
        reply = {"defect": str(exc)}
    out.write(json.dumps(reply) + "\n")
    out.flush()
"""


class PlotWorker:
    """A process without dolfinx that runs ``solver ARGV`` (plot) in itself for each request: the Python stderr and
    what native code (VTK) wrote on file descriptor 2 together are the stderr a user would see."""

    def __init__(self) -> None:
        self.proc: subprocess.Popen | None = None

    def __call__(self, argv: list[str]) -> tuple[int, str, str]:
        if self.proc is None or self.proc.poll() is not None:
            self.proc = subprocess.Popen([sys.executable, "-c", WORKER, str(ROOT)], cwd=ROOT, stdin=subprocess.PIPE,
                                         stdout=subprocess.PIPE, text=True)
        self.proc.stdin.write(json.dumps(argv) + "\n")
        self.proc.stdin.flush()
        line = self.proc.stdout.readline()
        if not line:
            code = self.proc.wait()
            self.proc = None
            raise Defect(f"solver {argv!r}: the process died (exit {code})")
        reply = json.loads(line)
        if "defect" in reply:
            raise Defect(reply["defect"])
        return reply["code"], reply["out"], reply["err"]

    def close(self) -> None:
        if self.proc is not None:
            self.proc.stdin.close()
            self.proc.wait(timeout=60)
            self.proc = None


def plot_command(worker: PlotWorker):
    return lambda directory: worker(["plot", str(directory)])


def paraview_command(directory: Path) -> tuple[int, str, str]:
    """``python -m solver paraview DIR`` as a user runs it (its own process; ParaView in another)."""
    res = subprocess.run([sys.executable, "-m", "solver", "paraview", str(directory)], cwd=ROOT, capture_output=True,
                         text=True, timeout=600)
    return res.returncode, res.stdout, res.stderr
