"""Fault injection for the XDMF writer (solver/io/xdmf.py), from the tests only: a kill or a full disk inside its writes.

In process: ``install("kill:data:6")`` or ``install("enospc:data:6")`` wraps the writer's file functions.
For a child process: ``python tests/faults.py SPEC -m solver run ...`` (or ``SPEC script.py args``)
installs SPEC, then runs the module or script as ``python`` would.

SPEC is ``action:stage:k``. ``action``: ``kill`` (SIGKILL this process) or ``enospc`` (raise OSError ENOSPC, as a
full disk does). ``stage``, counted per process from 1 in the body's series (solution.xdmf and its files; the writes of
contact.xdmf are neither counted nor faulted):

- ``data``: the k-th written level, after its first field is written (its chunk open, the level half done);
- ``close``: the k-th chunk, just after its file was written (complete, not yet listed in the XML);
- ``file``: the k-th file written, half of it: chunk files and XML temporaries alternate (chunk 1, the XML
  listing it, chunk 2, ...); a chunk file (written level by level) is cut to half once complete, not yet listed;
  a temporary is not yet renamed over solution.xdmf.
"""

from __future__ import annotations

import os
import runpy
import signal
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]


def _fault(action: str, path=None) -> None:
    if action == "kill":
        os.kill(os.getpid(), signal.SIGKILL)
    raise OSError(28, "No space left on device", str(path) if path else None)


def install(spec: str) -> None:
    """Wrap solver.io.xdmf's writing functions so that the fault ``spec`` happens (see the module docstring)."""
    import solver.io.xdmf as sx

    action, stage, k = spec.split(":")
    if action not in ("kill", "enospc") or stage not in ("data", "close", "file"):
        raise ValueError(f"fault {spec!r}: action kill|enospc, stage data|close|file")
    at, count = int(k), {"n": 0}

    def body(path) -> bool:
        """A file of the body's series: its chunks (fields/levels_*.h5) or its XML's temporary."""
        return Path(path).name.startswith(("levels_", ".solution.xdmf"))

    def hit() -> bool:
        count["n"] += 1
        return count["n"] == at

    if stage == "data":
        add, write_dataset, armed = sx._Chunk.add, sx._write_dataset, {"on": False}

        def add_level(self, *args, **kw):
            armed["on"] = body(self.path) and hit()
            return add(self, *args, **kw)

        def write_one(group, name, *args, **kw):
            write_dataset(group, name, *args, **kw)
            if armed["on"]:
                armed["on"] = False
                _fault(action)

        sx._Chunk.add, sx._write_dataset = add_level, write_one
    elif stage == "close":
        close = sx._close_chunk

        def close_chunk(chunk):
            close(chunk)
            if body(chunk.path) and hit():
                _fault(action, chunk.path)

        sx._close_chunk = close_chunk
    else:
        write_file, close = sx._write_file, sx._close_chunk

        def write_half(path, data):
            if body(path) and hit():
                write_file(path, data[: len(data) // 2])
                _fault(action, path)
            write_file(path, data)

        def close_half(chunk):  # a chunk's file is written level by level: its end cut off when it is complete
            close(chunk)
            if body(chunk.path) and hit():
                os.truncate(chunk.path, os.path.getsize(chunk.path) // 2)
                _fault(action, chunk.path)

        sx._write_file, sx._close_chunk = write_half, close_half


def command(spec: str, args: list[str]) -> list[str]:
    """The command that runs ``python ARGS`` with the fault ``spec`` installed."""
    return [sys.executable, str(Path(__file__).resolve()), spec, *args]


def main(argv: list[str]) -> None:
    spec, rest = argv[0], argv[1:]
    sys.path.insert(0, str(ROOT))
    install(spec)
    if rest[0] == "-m":
        sys.argv = [rest[1], *rest[2:]]
        runpy.run_module(rest[1], run_name="__main__", alter_sys=True)
    else:
        sys.argv = rest
        runpy.run_path(rest[0], run_name="__main__")


if __name__ == "__main__":
    main(sys.argv[1:])
