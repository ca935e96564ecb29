"""The CSV time series of a run (``timeseries.csv``): its writer (rank 0); its columns are
:func:`solver.io.layout.timeseries_columns`."""

from __future__ import annotations

import os
from pathlib import Path

from mpi4py import MPI

from solver.io.files import on_rank0, write_text_atomic
from solver.io.layout import KRYLOV_COLUMNS  # noqa: F401  (importers read the columns here too)
from solver.io.layout import TIMESERIES_COLUMNS as CSV_COLUMNS
from solver.run.stepper import TIMING_COLUMNS  # noqa: F401  (part of the columns' description)


class CSVWriter:
    """Rows of the time series, written by rank 0, each row one ``write()`` of a whole line.

    ``columns``: :func:`solver.io.layout.timeseries_columns` of the run (default: the fixed ones only).

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
