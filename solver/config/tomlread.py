"""Reading a scene's TOML text with tomllib, the big tables of numbers parsed by numpy.

tomllib parses a 10⁵-row table ``[[s, g], ...]`` in about 0.6 s (a fifth of a small run's whole command); numpy
reads the same numbers in milliseconds. :func:`loads` cuts each array of rows of plain numbers with more than
:data:`BIG` rows out of the text, parses the rest with tomllib and puts the rows back as lists of floats. Anything
it is not sure of (a sign of an unusual number, a comment in the array, the cut landing in a string) leaves the text
to tomllib whole, which then reads or refuses it as before; so the result is tomllib's, except that such a table is a
:class:`solver.config.tables.DataTable` (a tuple of tuples of floats to whoever reads it, its integers as floats: the
table keys read numbers as floats anyway), which keeps its text to write it back as it was.
"""

from __future__ import annotations

import re
import tomllib
from typing import Any

import numpy as np

from .tables import DataTable

BIG = 1000  # arrays of more rows are read by numpy
_START = re.compile(r"=[ \t]*(\[[ \t\r\n]*\[)")  # a value that is an array of arrays
_END = re.compile(r"\][ \t\r\n]*,?[ \t\r\n]*\]")  # the end of a row, then the end of the array
_PLAIN = re.compile(r"[0-9eE+\-., \t\r\n\[\]]*")  # the only characters a fast-read array may hold
_MARK = "@@campo-table-"


def _table(chars: str) -> np.ndarray:
    """A lookup table: byte -> whether it is one of ``chars``."""
    out = np.zeros(256, dtype=bool)
    out[np.frombuffer(chars.encode(), dtype=np.uint8)] = True
    return out


_DIGITS, _SEPS, _SIGNS, _EXP = _table("0123456789"), _table("[], \t\r\n"), _table("+-"), _table("eE")
_OPEN, _CLOSE, _COMMA, _DOT, _ZERO = (ord(c) for c in "[],.0")


def loads(text: str) -> dict:
    """The TOML document ``text`` as tomllib reads it, its big arrays of rows of numbers read by numpy."""
    if _MARK in text or len(text) < 20 * BIG:
        return tomllib.loads(text)
    cuts: list[tuple[int, int, list]] = []
    for m in _START.finditer(text):
        start = m.start(1)
        if cuts and start < cuts[-1][1]:
            continue
        rows = _rows(text, start)
        if rows is not None:
            cuts.append((start, rows[0], rows[1]))
    if not cuts:
        return tomllib.loads(text)
    parts, at = [], 0
    for i, (a, b, _) in enumerate(cuts):
        parts += [text[at:a], f'"{_MARK}{i}@@"']
        at = b
    parts.append(text[at:])
    try:
        doc = tomllib.loads("".join(parts))
    except tomllib.TOMLDecodeError:
        return tomllib.loads(text)  # its own error, with the text's own line numbers
    found: set[int] = set()
    doc = _put_back(doc, [rows for _, _, rows in cuts], found)
    if doc is None or len(found) != len(cuts):
        return tomllib.loads(text)  # a cut landed somewhere else than a value (a string): tomllib reads it all
    return doc


def _rows(text: str, start: int) -> tuple[int, list] | None:
    """(end, rows) of the array of rows starting at ``start`` if it holds more than BIG rows of numbers written as
    TOML writes decimal numbers (checked byte by byte with numpy: a sign only first or after an exponent, a dot only
    between digits, no leading zero)."""
    m = _END.search(text, start)
    if m is None:
        return None
    end = m.end()
    span = text[start:end]
    if span.count("[") <= BIG or _PLAIN.fullmatch(span) is None:
        return None
    b = np.frombuffer(span[1:-1].encode(), dtype=np.uint8)  # inside the outer brackets
    opens, closes = np.flatnonzero(b == _OPEN), np.flatnonzero(b == _CLOSE)
    if len(opens) != len(closes) or not (opens < closes).all() or not (closes[:-1] < opens[1:]).all():
        return None  # not [..], [..], ... one level deep
    marks = np.zeros(len(b), dtype=np.int8)
    marks[opens], marks[closes] = 1, -1
    inside = np.cumsum(marks, dtype=np.int8) > 0
    inside[opens] = False  # within a row, its brackets excluded
    comma = b == _COMMA
    between = np.count_nonzero(comma & ~inside)
    if between not in (len(opens) - 1, len(opens)) or (comma & ~inside)[: opens[0]].any():
        return None  # rows separated by one comma each (one more after the last)
    per_row = np.add.reduceat((comma & inside).astype(np.int32), opens)
    width = int(per_row[0]) + 1
    if (per_row != width - 1).any() or not _numbers(b, inside):
        return None
    cells = np.where(inside, b, ord(" ")).astype(np.uint8)  # the rows' cells, run together...
    cells[closes[:-1]] = _COMMA  # ...and separated by commas
    try:
        a = np.array(cells.tobytes().decode().split(","), dtype=float)
    except ValueError:
        return None
    if a.size != len(opens) * width or not np.isfinite(a).all():
        return None
    return end, DataTable(array=a.reshape(-1, width), text=span)


def _numbers(b: np.ndarray, inside: np.ndarray) -> bool:
    """Whether the characters inside the rows are decimal numbers as TOML writes them, separated by commas: each
    rule looked up around the positions of its character only (a dot, an exponent, a sign, a zero)."""
    if (~inside & ~_SEPS[b]).any():
        return False  # between the rows: separators only
    padded = np.concatenate(([ord(" ")] * 2, b, [ord(" ")] * 2)).astype(np.uint8)  # a separator before and after
    digit, sep = _DIGITS[padded], _SEPS[padded]

    def at(c: int) -> np.ndarray:
        return np.flatnonzero(padded == c)

    dots = at(_DOT)
    if not (digit[dots - 1] & digit[dots + 1]).all():
        return False
    exps = np.concatenate((at(ord("e")), at(ord("E"))))
    after = digit[exps + 1] | (_SIGNS[padded[exps + 1]] & digit[exps + 2])
    if not (digit[exps - 1] & after).all():
        return False
    signs = np.concatenate((at(ord("+")), at(ord("-"))))
    if not ((sep[signs - 1] | _EXP[padded[signs - 1]]) & digit[signs + 1]).all():
        return False
    zeros = at(_ZERO)
    starts = sep[zeros - 1] | (_SIGNS[padded[zeros - 1]] & sep[zeros - 2])  # a zero that starts a number
    return not (starts & digit[zeros + 1]).any()


def _put_back(v: Any, cuts: list, found: set[int]) -> Any:
    """``v`` with each mark replaced by its rows; None if a mark is not a whole value."""
    if isinstance(v, dict):
        out = {}
        for k, x in v.items():
            y = _put_back(x, cuts, found)
            if y is None and x is not None:
                return None
            out[k] = y
        return out
    if isinstance(v, list):
        out_list = []
        for x in v:
            y = _put_back(x, cuts, found)
            if y is None:
                return None
            out_list.append(y)
        return out_list
    if isinstance(v, str) and _MARK in v:
        m = re.fullmatch(re.escape(_MARK) + r"(\d+)@@", v)
        if m is None:
            return None
        found.add(int(m.group(1)))
        return cuts[int(m.group(1))]
    return v
