"""``contact.csv``: the contact results along Γ_C at each written level, so that p(s) plots without ParaView.

One row per node of the trace space on each contact part (the mesh's vertices for P1), in order along the
part: ``s`` the arc length from its first node, the point, the gap g, the normal displacement u_ν, the
penetration u_ν − g and the pressure λ_h (:class:`solver.physics.contact_traces.ContactTraces`). Rank 0
writes; the nodes of every rank are gathered to it.
"""

from __future__ import annotations

import os
from pathlib import Path

import numpy as np
from mpi4py import MPI

from solver.io.files import on_rank0, write_text_atomic
from solver.io.layout import PROFILE_COLUMNS
from solver.physics.contact_traces import ContactTraces

HEAD = 4  # the columns that are the same at every level: s and the point (x, y, z)


class ProfileWriter:
    """Appends each written level's profile to ``path``; ``keep_step`` (a restart) keeps the rows up to that step."""

    def __init__(self, path: Path, comm: MPI.Comm, traces: ContactTraces, keep_step: int | None = None) -> None:
        self.path, self.comm, self.traces = path, comm, traces
        self.fd: int | None = None  # rank 0: the file, open for appending while the run lasts
        self._templates: dict[str, tuple[bytes, str]] = {}  # rank 0: per part, its lines' format (_template)

        def start() -> None:
            kept = []
            if keep_step is not None and path.exists():
                kept = [ln for ln in path.read_text().splitlines(keepends=True)[1:]
                        if ln.endswith("\n") and int(ln.split(",", 1)[0]) <= keep_step]
            write_text_atomic(path, ",".join(PROFILE_COLUMNS) + "\n" + "".join(kept))
            self.fd = os.open(path, os.O_WRONLY | os.O_APPEND)
            self.size = os.fstat(self.fd).st_size

        on_rank0(comm, start)

    def write(self, step: int, t: float) -> None:
        """The profile of the current level (the traces as the level's diagnostics left them)."""
        parts = self.traces.profile()  # collective

        def append() -> None:
            lead = f"{step},{float(t)!r},".replace("%", "%%")
            data = "".join(self._template(name, rows).replace("\0", lead) % tuple(rows[:, HEAD:].ravel().tolist())
                           for name, rows in parts).encode()
            try:
                if os.write(self.fd, data) != len(data):
                    raise OSError(28, "No space left on device (short write)", str(self.path))
            except OSError:
                os.ftruncate(self.fd, self.size)  # no partial level
                raise
            self.size += len(data)

        on_rank0(self.comm, append)

    def _template(self, name: str, rows: np.ndarray) -> str:
        """A part's lines with its fixed columns (s and the point) written out, \\0 for the lead (step, t) and %r
        for each of the others: a level is one % format, the same text as repr of each value (its fixed columns'
        reprs made once). Made again if the fixed columns change."""
        head = np.ascontiguousarray(rows[:, :HEAD])
        kept = self._templates.get(name)
        if kept is None or kept[0] != head.tobytes():
            tail = ",%r" * (rows.shape[1] - HEAD) + "\n"
            text = "".join("\0" + (name + "," + ",".join(map(repr, row))).replace("%", "%%") + tail
                           for row in head.tolist())
            kept = self._templates[name] = (head.tobytes(), text)
        return kept[1]

    def close(self) -> None:
        if self.fd is not None:
            os.close(self.fd)
            self.fd = None
