"""Tables of rows as data: inline TOML arrays ``[[a, b], ...]`` or CSV files ``{file = "profile.csv", columns = [...]}``.

Every table key (a contact part's gap, a traction, a displacement component, the body force, the memory kernel's
table) reads its rows here. A CSV file is read with numpy; its path is relative to the scene file, ``#`` starts a
comment line, a first line that is not all numbers is a header naming the columns, and ``columns`` picks the
columns in the order the key wants them, by header name or by number (the first column is 1). Each error is one
line naming the file, the line and the column. A table read from a file is a :class:`DataTable`: a tuple of rows
that remembers its file, so the resolved scene written beside the results refers to a copy of the data
(:func:`solver.config.scene.dumps_referring`) instead of inlining it.
"""

from __future__ import annotations

import math
import os
import shutil
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from solver.errors import ConfigError

from .fields import Ctx, check_keys, string

TABLE_KEYS = ("file", "columns")


@dataclass(frozen=True)
class TableFile:
    """Where a table's rows came from: the file (resolved), the columns as given (() : all, in order), and the
    file's size and modification time when it was read (a copy of the file is its rows while they match)."""

    path: str
    columns: tuple[str | int, ...] = ()
    stamp: tuple[int, int] = (0, 0)


class DataTable(Sequence):
    """A table's rows held as a read-only (rows, columns) float array (:attr:`array`), seen as a tuple of tuples of
    floats: ``len``, indexing (a row is a tuple), iteration, and equality with the same rows inline (a tuple of
    tuples). A 10⁵-row table is then never 10⁵ Python tuples (0.1–0.2 s to make, and to hash at every cache look-up).
    Read from a file it remembers it (``file``) and its columns' names (``labels``); read inline by the scene reader,
    its TOML text (``text``), written back as it is. Immutable: copies are itself.
    """

    __slots__ = ("_array", "file", "labels", "text", "_hash")

    def __init__(self, rows: Any = (), file: TableFile | None = None, labels: tuple[str, ...] = (),
                 array: np.ndarray | None = None, text: str | None = None) -> None:
        a = np.array(list(rows), dtype=float, ndmin=2) if array is None else np.asarray(array, dtype=float)
        if a.size == 0:
            a = a.reshape(0, 0)
        a.flags.writeable = False
        self._array, self.file, self.labels, self.text = a, file, tuple(labels), text
        self._hash: int | None = None

    @property
    def array(self) -> np.ndarray:
        """The rows as a read-only (rows, columns) float array."""
        return self._array

    def __array__(self, dtype=None) -> np.ndarray:
        return self._array if dtype is None else self._array.astype(dtype)

    def __len__(self) -> int:
        return len(self._array)

    def __getitem__(self, i):
        if isinstance(i, slice):
            return tuple(map(tuple, self._array[i].tolist()))
        return tuple(self._array[i].tolist())

    def __iter__(self):
        return map(tuple, self._array.tolist())

    def __eq__(self, other: object) -> bool:
        if isinstance(other, DataTable):
            return self._array.shape == other._array.shape and bool(np.array_equal(self._array, other._array))
        if isinstance(other, (tuple, list)):
            return len(other) == len(self) and all(tuple(a) == tuple(b) for a, b in zip(self, other))
        return NotImplemented

    def __hash__(self) -> int:
        """The hash of the tuple of tuples it equals (computed once)."""
        if self._hash is None:
            self._hash = hash(tuple(self))
        return self._hash

    def __repr__(self) -> str:
        where = f" from {self.file.path}" if self.file is not None else ""
        return f"DataTable({len(self)} rows{where})"

    def __reduce__(self):
        return (DataTable, ((), self.file, self.labels, self._array, self.text))

    def __copy__(self) -> DataTable:
        return self

    def __deepcopy__(self, memo) -> DataTable:
        return self


def as_array(rows: tuple) -> np.ndarray:
    """A table's rows as a float array (a DataTable's own, without copying)."""
    return rows.array if isinstance(rows, DataTable) else np.asarray(rows, dtype=float)


def rows_given(v: Any) -> bool:
    """Whether a table key's value is rows given inline: a list of lists, or the scene reader's big table."""
    return isinstance(v, DataTable) or (isinstance(v, list) and bool(v) and all(isinstance(r, list) for r in v))


def given_as_file(v: Any) -> bool:
    """Whether a table key's value is a file reference (an inline table ``{file = ...}``)."""
    return isinstance(v, dict)


def row_error(ctx: Ctx, key: str, rows: tuple, i: int, value: Any, allowed: str) -> ConfigError:
    """A one-line error about row ``i`` of a table: at its file's line for a file's, at ``key`` (row i, counted from
    0 as in ``key[i]``) for an inline one."""
    if isinstance(rows, DataTable) and rows.file is not None:
        lines = _data_lines(Path(rows.file.path).read_text(encoding="utf-8"))[0]
        return ConfigError(source=f"{rows.file.path}:{lines[i][0]}", key=key, value=value, allowed=allowed)
    return ConfigError(source=ctx.source, key=key, value=value, allowed=f"{allowed} (at {key}[{i}])")


def inline(ctx: Ctx, key: str, v: list, width: int, what: str) -> tuple[tuple[float, ...], ...]:
    """Rows of ``width`` finite numbers given inline; the error names the first bad row (``what``: the row's form).

    Whole arrays are checked by numpy first (a 10⁵-row table in a few milliseconds; rows the scene reader already
    read with numpy are taken as they are); only a failing one is walked row by row to name its first bad entry."""
    if isinstance(v, DataTable):  # read by the scene reader (solver.config.tomlread): numbers already
        if v.array.shape[1] != width:
            raise ctx.fail(f"{key}[0]", list(v[0]), f"must be a row {what}: {width} numbers")
        return v
    if all(type(r) is list and len(r) == width and all(type(x) in (float, int) for x in r) for r in v):
        a = np.asarray(v, dtype=float)
        if a.ndim == 2 and np.isfinite(a).all():
            return DataTable(array=a)
    from .fields import vector  # the row-by-row check names the first bad row

    return tuple(_row(ctx, f"{key}[{i}]", r, width, what, vector) for i, r in enumerate(v))


def _row(ctx: Ctx, key: str, r: Any, width: int, what: str, vector) -> tuple[float, ...]:
    if not isinstance(r, list):
        raise ctx.fail(key, r, f"must be a row {what}")
    return vector(ctx, key, r, width)


def read_csv(ctx: Ctx, key: str, v: Any, base: Path, labels: tuple[str, ...]) -> DataTable:
    """The rows of the CSV file ``v = {file, columns}`` (``labels``: the names of the columns the key wants, which
    also fix their number)."""
    width = len(labels)
    v = check_keys(ctx, key, v, TABLE_KEYS)
    if "file" not in v:
        raise ctx.fail(f"{key}.file", "<missing>", f"a table from a file is {{file = \"table.csv\", columns = "
                       f"[{', '.join(repr(x) for x in labels)}]}}")
    name = string(ctx, f"{key}.file", v["file"])
    path = Path(name) if Path(name).is_absolute() else base / name
    columns = _columns(ctx, f"{key}.columns", v.get("columns"), width)
    try:
        text = path.read_text(encoding="utf-8")
    except UnicodeDecodeError:
        raise ctx.fail(f"{key}.file", name, f"not a text (UTF-8) file ({path})") from None
    except OSError as exc:
        raise ctx.fail(f"{key}.file", name, f"cannot read it ({path}: {exc.strerror or exc})") from None
    src = str(path)
    numbers, header = _data_lines(text, first_only=True)
    if not numbers:
        raise ConfigError(source=src, key=key, value=name, allowed="the file holds no rows of numbers")
    ncols = len(header[1]) if header else numbers[0][1].count(",") + 1
    picked = _pick(ctx, key, src, columns, header, ncols, width, labels)
    try:  # numpy's reader over the whole file; the lines are walked only to name a bad one
        a = np.loadtxt(path, delimiter=",", comments="#", skiprows=header[0] if header else 0, dtype=float, ndmin=2,
                       encoding="utf-8")
        ok = a.shape[1] == ncols
    except ValueError:
        ok = False
    if not ok:
        _locate(src, key, _data_lines(text)[0], ncols, header)  # raises, naming the line and column
    bad = ~np.isfinite(a)
    if bad.any():
        i, j = np.argwhere(bad)[0]
        line = _data_lines(text)[0][i][0]
        raise ConfigError(source=f"{src}:{line}", key=key, value=float(a[i, j]),
                          allowed=f"column {j + 1}{_named(header, j)} must be a finite number")
    rows = np.ascontiguousarray(a[:, picked])
    rows.flags.writeable = False
    names = tuple(header[1][j] for j in picked) if header else labels
    stat = path.stat()
    return DataTable((), TableFile(str(path.resolve()), columns, (stat.st_size, stat.st_mtime_ns)), names, rows)


def _data_lines(text: str, first_only: bool = False) -> tuple[list[tuple[int, str]], tuple[int, list[str]] | None]:
    """The (line number, text) of a CSV text's data lines (blank and ``#`` lines skipped) and its header (line
    number, names) if its first such line is not all numbers; ``first_only``: stop at the first data line."""
    numbers: list[tuple[int, str]] = []
    header = None
    for n, line in enumerate(text.splitlines(), 1):
        s = line.strip()
        if not s or s.startswith("#"):
            continue
        if header is None and not numbers and not _all_numbers(s):
            header = (n, [c.strip() for c in s.split(",")])
            continue
        numbers.append((n, s))
        if first_only:
            break
    return numbers, header


def _all_numbers(line: str) -> bool:
    try:
        [float(c) for c in line.split(",")]
    except ValueError:
        return False
    return True


def _columns(ctx: Ctx, key: str, v: Any, width: int) -> tuple[str | int, ...]:
    if v is None:
        return ()
    if not isinstance(v, list) or len(v) != width:
        raise ctx.fail(key, v, f"must list {width} columns, each a header name or a number (the first column is 1)")
    for i, c in enumerate(v):
        ok = (isinstance(c, str) and c) or (isinstance(c, int) and not isinstance(c, bool) and c >= 1)
        if not ok:
            raise ctx.fail(f"{key}[{i}]", c, "a column is a header name or a number (the first column is 1)")
    return tuple(v)


def _pick(ctx: Ctx, key: str, src: str, columns: tuple, header, ncols: int, width: int,
          labels: tuple[str, ...]) -> list[int]:
    """The 0-based indices of the columns the key reads."""
    if not columns:
        if ncols != width:
            raise ConfigError(source=src, key=key, value=f"{ncols} columns", allowed=(
                f"needs {width} columns ({', '.join(labels)}), or columns = [...] naming which"))
        return list(range(width))
    out = []
    for i, c in enumerate(columns):
        if isinstance(c, int):
            if c > ncols:
                raise ctx.fail(f"{key}.columns[{i}]", c, f"the file has {ncols} columns ({src})")
            out.append(c - 1)
            continue
        names = header[1] if header else []
        if names.count(c) != 1:
            has = f"its header has {', '.join(names)}" if header else "it has no header line"
            many = "more than one column" if names.count(c) > 1 else "no column"
            raise ctx.fail(f"{key}.columns[{i}]", c, f"{many} of that name in {src} ({has})")
        out.append(names.index(c))
    return out


def _named(header, j: int) -> str:
    return f" ({header[1][j]})" if header and j < len(header[1]) else ""


def _locate(src: str, key: str, numbers: list[tuple[int, str]], ncols: int, header) -> None:
    """Raise the error of the first line whose cells are not ``ncols`` numbers."""
    for n, s in numbers:
        cells = s.split(",")
        if len(cells) != ncols:
            raise ConfigError(source=f"{src}:{n}", key=key, value=s[:80],
                              allowed=f"has {len(cells)} columns where the file has {ncols}")
        for j, c in enumerate(cells):
            try:
                x = float(c)
            except ValueError:
                raise ConfigError(source=f"{src}:{n}", key=key, value=c.strip()[:80],
                                  allowed=f"column {j + 1}{_named(header, j)} must be a number") from None
            if not math.isfinite(x):
                raise ConfigError(source=f"{src}:{n}", key=key, value=x,
                                  allowed=f"column {j + 1}{_named(header, j)} must be a finite number")
    raise ConfigError(source=src, key=key, value="<rows>", allowed="numpy cannot read it as comma-separated numbers")


def unchanged(rows: DataTable) -> bool:
    """Whether a table's file is still as it was read (size and modification time): then a copy of it is its rows."""
    if rows.file is None:
        return False
    try:
        stat = os.stat(rows.file.path)
    except OSError:
        return False
    return (stat.st_size, stat.st_mtime_ns) == rows.file.stamp


def reference(rows: DataTable, name: str, as_file: bool) -> dict[str, Any]:
    """How a resolved scene refers to the copy ``name`` of a file's table (:func:`write_copy`): the file's columns
    when it is copied as it is (``as_file``), all in order when its rows are written."""
    ref: dict[str, Any] = {"file": name}
    if as_file and rows.file is not None and rows.file.columns:
        ref["columns"] = list(rows.file.columns)
    return ref


def write_copy(rows: DataTable, target: Path, as_file: bool) -> None:
    """Write a file's table to ``target`` through a temporary name: the file itself (``as_file``: it is
    :func:`unchanged`), else its rows (:func:`to_csv`). Nothing is written onto the file itself."""
    if as_file and rows.file is not None and Path(rows.file.path).resolve() == target.resolve():
        return
    tmp = target.with_name(target.name + ".tmp")
    if as_file and rows.file is not None:
        shutil.copyfile(rows.file.path, tmp)
    else:
        tmp.write_text(to_csv(rows))
    os.replace(tmp, target)


def to_csv(rows: DataTable) -> str:
    """The CSV text of a table: a header of its labels, then its rows, each number as Python writes it back exactly."""
    labels = rows.labels if rows.labels and not _all_numbers(",".join(rows.labels)) else ()
    head = ",".join(labels) + "\n" if labels else ""
    return head + "".join(",".join(map(repr, r)) + "\n" for r in rows)
