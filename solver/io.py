"""Writers beside the XDMF series (solver/xdmf.py): CSV time series and resolved config (rank 0), von Mises."""

from __future__ import annotations

import os
from collections.abc import Callable
from pathlib import Path

import numpy as np
from mpi4py import MPI

from .errors import OutputError
from .xdmf import describe_oserror

CSV_COLUMNS = (
    "step", "t", "newton_iterations", "linear_solves", "factorizations", "residual", "contact_force",
    "contact_length", "max_penetration", "zeta_min", "zeta_max", "zeta_raw_min", "zeta_raw_max", "zeta_clipped",
    "strain_norm", "zeta_norm", "time_damage", "time_memory", "time_displacement", "time_diagnostics", "time_output",
    "wall_time",
)
# with solver.linear resolving to "iterative": the Krylov iterations of the level's displacement solves (summed
# over its Newton iterations) and of its damage solve; they follow CSV_COLUMNS, before the reaction columns
KRYLOV_COLUMNS = ("krylov_iterations", "damage_krylov_iterations")
TIMING_COLUMNS = ("time_damage", "time_memory", "time_displacement", "time_diagnostics", "time_output", "wall_time")


def von_mises_array(s: np.ndarray, dim: int, s33: np.ndarray | None = None) -> np.ndarray:
    """von Mises of an array of tensors (n, dim*dim): the paper's plane formula in 2-D; with the
    out-of-plane stresses ``s33`` (plane strain) the full one, sqrt(((a-b)^2 + (b-c)^2 + (c-a)^2)/2 + 3 t^2)."""
    s = s.reshape(-1, dim, dim)
    if dim == 2 and s33 is not None:
        a, b, c, t = s[:, 0, 0], s[:, 1, 1], s33, s[:, 0, 1]
        return np.sqrt(((a - b) ** 2 + (b - c) ** 2 + (c - a) ** 2) / 2 + 3 * t * t)
    if dim == 2:
        a, b, c = s[:, 0, 0], s[:, 1, 1], s[:, 0, 1]
        return np.sqrt(a * a + b * b - a * b + 3 * c * c)
    dev = s - np.trace(s, axis1=1, axis2=2)[:, None, None] * np.eye(3) / 3
    return np.sqrt(1.5 * np.einsum("nij,nij->n", dev, dev))


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


class CSVWriter:
    """Rows of the time series, written by rank 0, each row one ``write()`` of a whole line.

    ``columns``: CSV_COLUMNS and the scene's own (the reactions of its Dirichlet parts).

    The file is opened in append mode and every row goes out in a single system call, so
    a killed run leaves only complete rows; a row that does not fit on the disk is cut off
    again (OSError). ``keep`` lines (a restart's rows up to its checkpoint, as written) are
    rewritten first, atomically.
    """

    def __init__(self, path: Path, comm: MPI.Comm, keep: list[str] | None = None,
                 columns: tuple[str, ...] = CSV_COLUMNS) -> None:
        self.comm = comm
        self.fd = None
        self.columns = columns

        def start() -> None:
            write_text_atomic(path, ",".join(columns) + "\n" + "".join(keep or []))
            self.fd = os.open(path, os.O_WRONLY | os.O_APPEND)
            self.size = os.fstat(self.fd).st_size

        on_rank0(comm, start)

    def write(self, row: dict) -> None:
        """Append one row (rank 0; the others do nothing)."""
        if self.fd is None:
            return
        data = _line(row, self.columns).encode()
        try:
            if os.write(self.fd, data) != len(data):
                raise OSError(28, "No space left on device (short write)", None)
        except OSError:
            os.ftruncate(self.fd, self.size)  # no partial row
            raise
        self.size += len(data)

    def close(self) -> None:
        if self.fd is not None:
            os.close(self.fd)
            self.fd = None


def _line(row: dict, columns: tuple[str, ...] = CSV_COLUMNS) -> str:
    return ",".join(_fmt(row[k]) for k in columns) + "\n"


def _fmt(v) -> str:
    if isinstance(v, float):
        return repr(v)
    return str(v)


def write_text_atomic(path: Path, text: str) -> None:
    """Write a small file through a temporary name and a rename."""
    tmp = path.with_name(path.name + ".tmp")
    with open(tmp, "w") as fh:
        fh.write(text)
        fh.flush()
        os.fsync(fh.fileno())
    os.replace(tmp, path)

