"""Small file operations every writer shares: rank 0 writes, its failure reaches every rank; atomic replacement."""

from __future__ import annotations

import os
from collections.abc import Callable
from pathlib import Path

from mpi4py import MPI

from solver.errors import OutputError
from solver.io.xdmf import describe_oserror


def on_rank0(comm: MPI.Comm, action: Callable[[], None]) -> None:
    """Run ``action`` on rank 0; an OSError there (a full disk) is raised as OutputError on every rank.

    Files are written by rank 0 alone, so its failure must reach the other ranks, or they
    would wait for it at their next collective call.
    """
    error = None
    if comm.rank == 0:
        try:
            action()
        except OSError as exc:
            error = describe_oserror(exc)
    if comm.size > 1:
        error = comm.bcast(error, root=0)
    if error is not None:
        raise OutputError(error)


def write_text_atomic(path: Path, text: str) -> None:
    """Write a small file through a temporary name and a rename."""
    tmp = path.with_name(path.name + ".tmp")
    with open(tmp, "w") as fh:
        fh.write(text)
        fh.flush()
        os.fsync(fh.fileno())
    os.replace(tmp, path)
