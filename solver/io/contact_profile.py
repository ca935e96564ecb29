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
U_NORMAL, PENETRATION = PROFILE_COLUMNS.index("u_normal") - 3, PROFILE_COLUMNS.index("penetration") - 3  # in a part's rows


class ProfileWriter:
    """Appends each written level's profile to ``path``; ``keep_step`` (a restart) keeps the rows up to that step."""

    def __init__(self, path: Path, comm: MPI.Comm, traces: ContactTraces, keep_step: int | None = None) -> None:
        self.path, self.comm, self.traces = path, comm, traces
        self.fd: int | None = None  # rank 0: the file, open for appending while the run lasts
        self._templates: dict[str, tuple[bytes, str]] = {}  # rank 0: per part, its lines' format with the gap fixed
        self._heads: dict[str, tuple[bytes, str]] = {}  # ... with s and the point fixed only (_template)
        self._previous: dict[str, bytes] = {}  # ... the fixed columns (with the gap) of the last level formatted

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
            text = []
            for name, rows in parts:
                template, fixed = self._template(name, rows)
                text.append(template.replace("\0", lead) % _reprs(rows, fixed))
            data = "".join(text).encode()
            try:
                if os.write(self.fd, data) != len(data):
                    raise OSError(28, "No space left on device (short write)", str(self.path))
            except OSError:
                os.ftruncate(self.fd, self.size)  # no partial level
                raise
            self.size += len(data)

        on_rank0(self.comm, append)

    def _template(self, name: str, rows: np.ndarray) -> tuple[str, int]:
        """A part's lines with its fixed columns written out, \\0 for the lead (step, t) and %s for each of the others,
        and the number of fixed columns: a level is one % format of their reprs (:func:`_reprs`; the fixed
        columns' reprs made once). Fixed: s and the point, and the gap once two levels in a row had the same (a gap
        that moves is formatted per level). Made again when they change."""
        fixed = np.ascontiguousarray(rows[:, : HEAD + 1]).tobytes()
        kept = self._templates.get(name)
        if kept is not None and kept[0] == fixed:
            return kept[1], HEAD + 1
        if self._previous.get(name) == fixed:  # the same gap again: part of the template from now on
            self._templates[name] = (fixed, self._lines(name, rows, HEAD + 1))
            return self._templates[name][1], HEAD + 1
        self._previous[name] = fixed
        head = np.ascontiguousarray(rows[:, :HEAD]).tobytes()
        kept = self._heads.get(name)
        if kept is None or kept[0] != head:
            kept = self._heads[name] = (head, self._lines(name, rows, HEAD))
        return kept[1], HEAD

    @staticmethod
    def _lines(name: str, rows: np.ndarray, fixed: int) -> str:
        """The lines of a part with its first ``fixed`` columns written out (repr), \\0 for the lead and %s for the
        others' reprs."""
        tail = ",%s" * (rows.shape[1] - fixed) + "\n"
        return "".join("\0" + (name + "," + ",".join(map(repr, row))).replace("%", "%%") + tail
                       for row in rows[:, :fixed].tolist())

    def close(self) -> None:
        if self.fd is not None:
            os.close(self.fd)
            self.fd = None


def _reprs(rows: np.ndarray, fixed: int) -> tuple[str, ...]:
    """repr of each value of ``rows[:, fixed:]``, row by row: a penetration with the same bits as its u_ν (no gap,
    or the lumped mean of a positive part that is u_ν itself: most rows in contact) takes u_ν's string instead of a
    second repr (the shortest round-trip repr, some 0.5-1 us a value, is most of a level's profile)."""
    values = rows[:, fixed:]
    width = values.shape[1]
    lists = values.T.tolist()
    pen = PENETRATION - fixed if fixed <= U_NORMAL else -1
    columns = [None if k == pen else list(map(repr, column)) for k, column in enumerate(lists)]
    if pen >= 0:
        un = U_NORMAL - fixed
        same = values[:, pen].view(np.int64) == values[:, un].view(np.int64)
        if same.all():
            columns[pen] = columns[un]
        else:
            columns[pen] = [a if s else repr(b) for a, s, b in zip(columns[un], same.tolist(), lists[pen])]
    flat: list[str] = [""] * (len(values) * width)
    for k, column in enumerate(columns):
        flat[k::width] = column
    return tuple(flat)
