"""``python -m solver paraview RESULTS_DIR [--field F] [--time T] [--warp W] [--output PNG] [--size W H]``.

Renders a results directory with ParaView's ``pvbatch`` (or ``pvpython``) running ``paraview_script.py`` (next to this
file); the arguments are passed through unchanged (``--help`` lists them). Debian's ParaView renders through X only,
so without a display we start a private ``Xvfb`` (package ``xvfb``) for the render. No dolfinx, no VTK here.
"""

from __future__ import annotations

import importlib.util
import os
import shutil
import subprocess
import sys
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path

from solver.errors import UsageError
from solver.io.layout import check_writable
from solver.io.xdmf import read_series

SCRIPT = Path(__file__).with_name("paraview_script.py")
NOT_INSTALLED = "error: ParaView's pvbatch is not installed (Debian: apt-get install paraview python3-paraview xvfb)"
# variables of the caller's MPI launch or Python that must not leak into ParaView's own MPI and Python
_DROP_PREFIXES = ("OMPI_", "PMIX_", "PMI_", "MPICH_", "HYDRA_", "I_MPI_")
_DROP = ("PYTHONPATH", "PYTHONHOME", "VIRTUAL_ENV")
# the private Xvfb's options: "-noreset" keeps the server up when its last client leaves; with a reset pvbatch's
# connection may come during it ("bad X server connection", SIGABRT: docs/developer/design-notes.md)
XVFB_OPTIONS = ("-screen", "0", "1920x1200x24", "-nolisten", "tcp", "-noreset")


def executable() -> str | None:
    """Path of ``pvbatch``, else ``pvpython``, on PATH (None if neither)."""
    return shutil.which("pvbatch") or shutil.which("pvpython")


def available() -> bool:
    """True if ParaView's ``pvbatch`` or ``pvpython`` is on PATH."""
    return executable() is not None


def python_problem(exe: str | None = None) -> str | None:
    """None if ParaView's ``pvbatch`` can import its Python modules, else the one-line reason (runs ``--check``).

    Debian's ``paraview`` package ships ``pvbatch`` but not the modules (``python3-paraview``).
    """
    exe = exe or executable()
    if exe is None:
        return NOT_INSTALLED
    try:
        res = subprocess.run(command(["--check"], exe), env=environment(), capture_output=True, text=True, timeout=120)
    except (OSError, subprocess.TimeoutExpired) as exc:
        return f"error: {exe} --check failed ({exc})"
    if res.returncode == 0:
        return None
    lines = [ln for ln in res.stderr.splitlines() if ln.startswith("error:")]
    return lines[-1] if lines else f"error: {exe} failed (exit {res.returncode}): {res.stderr.strip()[-300:]}"


def has_display() -> bool:
    """True if an X (or Wayland) display is set."""
    return bool(os.environ.get("DISPLAY") or os.environ.get("WAYLAND_DISPLAY"))


def command(argv: list[str], exe: str | None = None) -> list[str]:
    """``pvbatch --force-offscreen-rendering paraview_script.py ARGV`` (the display is up to the caller)."""
    exe = exe or executable()
    if exe is None:
        raise FileNotFoundError("pvbatch")
    return [exe, "--force-offscreen-rendering", str(SCRIPT), *argv]


def environment() -> dict[str, str]:
    """The caller's environment without MPI launcher and Python path variables."""
    return {k: v for k, v in os.environ.items() if k not in _DROP and not k.startswith(_DROP_PREFIXES)}


@contextmanager
def virtual_display(xvfb: str) -> Iterator[str]:
    """A private Xvfb server for the duration of the block; yields its DISPLAY (``:N``).

    ``-displayfd`` lets the server choose a free display number and report it once it accepts connections, so
    concurrent renders do not race for a number as ``xvfb-run -a`` can.
    """
    read, write = os.pipe()
    proc = subprocess.Popen([xvfb, "-displayfd", str(write), *XVFB_OPTIONS],
                            pass_fds=(write,), stdin=subprocess.DEVNULL, stdout=subprocess.DEVNULL,
                            stderr=subprocess.DEVNULL)
    os.close(write)
    try:
        with os.fdopen(read) as pipe:
            number = pipe.readline().strip()  # blocks until the server is ready (or has died)
        if not number:
            raise RuntimeError(f"{xvfb} did not start (exit code {proc.wait(timeout=10)})")
        yield f":{number}"
    finally:
        if proc.poll() is None:
            proc.terminate()
            try:
                proc.wait(timeout=10)
            except subprocess.TimeoutExpired:
                proc.kill()
                proc.wait()


def check_results(argv: list[str]) -> int | None:
    """The script's command line parsed here, and the directory checked, before ParaView starts: an exit code for
    a command line argparse ends (``--help``: 0; a bad option: 2, its usage and error printed), else None. A
    damaged results directory is a :class:`ResultsError` (the file and what is wrong), an output that cannot be
    written a :class:`UsageError`: VTK's readers print pages of
    errors, or abort, on a truncated ``.h5`` or an XDMF naming a missing file. The XML and every dataset's presence,
    type and shape are checked with h5py; the field values are not read."""
    spec = importlib.util.spec_from_file_location("paraview_script", SCRIPT)
    script = importlib.util.module_from_spec(spec)
    path = list(sys.path)
    try:
        spec.loader.exec_module(script)
        args = script.parse_args(argv)
    except SystemExit as exc:
        return exc.code if isinstance(exc.code, int) else 2
    finally:
        sys.path[:] = path  # the script drops this folder from the path
    given = Path(args.results)
    series = given / "solution.xdmf" if given.is_dir() else given
    if series.is_file():  # no solution.xdmf: the script says so, after saying ParaView's Python modules are missing
        read_series(series, values=False)
        out = Path(args.output) if args.output else series.parent / f"paraview_{args.field}.png"
        what = f"--output {out}" if args.output else f"{out.parent} (give --output elsewhere)"
        check_writable(out.parent, what)
        if out.exists() and not os.access(out, os.W_OK):
            raise UsageError(f"{what}: cannot write {out.name} there (Permission denied)")
    return None


def main(argv: list[str] | None = None) -> int:
    """Run the ParaView render with ``argv`` (default ``sys.argv[1:]``); returns its exit code (2 if ParaView is missing)."""
    argv = list(sys.argv[1:] if argv is None else argv)
    exe = executable()
    if exe is None and not {"-h", "--help"} & set(argv):  # the help needs no ParaView
        print(NOT_INSTALLED, file=sys.stderr)
        return 2
    try:
        code = check_results(argv)
    except UsageError as exc:
        print(f"error: {exc}", file=sys.stderr)
        return 2
    if code is not None:
        return code
    cmd, env = command(argv, exe), environment()
    sys.stdout.flush()
    xvfb = shutil.which("Xvfb")
    if has_display() or xvfb is None:  # a display, or hope for a headless (EGL/OSMesa) ParaView build
        code = subprocess.run(cmd, env=env, check=False).returncode
        if code not in (0, 2) and not has_display():
            print("error: ParaView failed; without a display Debian's pvbatch needs Xvfb (apt-get install xvfb)",
                  file=sys.stderr)
        return code
    # a crash (pvbatch has aborted while opening its window) is retried once on a fresh virtual display; the script's
    # own refusals (exit 2: bad directory, field or option, ParaView's Python
    # modules missing) are not
    code = 1
    for attempt in range(2):
        try:
            with virtual_display(xvfb) as display:
                code = subprocess.run(cmd, env={**env, "DISPLAY": display}, check=False).returncode
        except RuntimeError as exc:
            print(f"error: {exc}", file=sys.stderr)
            return 1
        if code in (0, 2):
            return code
        if attempt == 0:
            print(f"ParaView failed (exit {code}); retrying once on a fresh virtual display", file=sys.stderr)
    return code


if __name__ == "__main__":
    sys.exit(main())
