"""Read a CSV sensor log (a header row naming the columns, one of them ``t`` in seconds, then numbers)
into a float64 table, refusing a bad file with the line and column of the first problem.

Accepted: UTF-8 text (a byte-order mark is fine), columns separated by commas, semicolons, tabs or
spaces (whichever the header uses), ``#`` comments and blank lines, ``nan``/``inf`` in data columns.
Refused, each with ``file:line:col``: a binary or non-UTF-8 file, a header without ``t``, duplicate
or empty column names, a row with too few or too many values, a cell that is not a number, a time
that is not finite or that goes back.
"""

from __future__ import annotations

import functools
import os
import warnings
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from flowtact.errors import FlowtactError

__all__ = ["CsvError", "CsvLog", "read_csv_log"]

TIME = "t"
#: Header names that look like a time column but are not called ``t``: named in the hint.
_TIME_LIKE = ("time", "time_s", "t_s", "timestamp", "times", "T", "Time", "TIME", "seconds", "sec")


class CsvError(FlowtactError, ValueError):
    """A CSV log that cannot be read: ``where`` is (display path, line, column), 1-based."""

    def __init__(self, path: str, line: int, col: int, message: str) -> None:
        self.where = (path, line, col)
        self.message = message
        super().__init__(f"{path}:{line}:{col}: {message}")


@dataclass(frozen=True)
class CsvLog:
    """A parsed log: column names (header order), the table (rows x columns) and its times."""

    path: Path
    names: tuple[str, ...]
    table: np.ndarray

    @property
    def t(self) -> np.ndarray:
        return self.table[:, self.names.index(TIME)]

    @property
    def data_columns(self) -> tuple[str, ...]:
        return tuple(n for n in self.names if n != TIME)

    def column(self, name: str) -> np.ndarray:
        return self.table[:, self.names.index(name)]


def display(path: str | Path) -> str:
    """``path`` as the user would write it: relative to the working directory when inside it."""
    rel = os.path.relpath(path)
    return str(path) if rel.startswith("..") else rel


def read_csv_log(path: str | Path) -> CsvLog:
    """Parse ``path``; raise :class:`CsvError` at the first problem (cached per file version)."""
    st = os.stat(path)
    return _read(str(path), st.st_mtime_ns, st.st_size)


@functools.lru_cache(maxsize=4)
def _read(path: str, _mtime_ns: int, _size: int) -> CsvLog:
    """One parse per file version: the replay of each port of a node reads the same table."""
    name = display(path)
    raw = Path(path).read_bytes()
    text = _decode(raw, name)
    lines = text.split("\n")
    head = next((i for i, s in enumerate(lines) if s.strip()), None)
    if head is None:
        raise CsvError(
            name, 1, 1, "the file is empty; a header row naming the columns (one of them 't') comes first"
        )
    names, delimiter = _header(lines[head], name, head + 1)
    body = lines[head + 1 :]
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")  # a header-only file is fine: zero rows
        try:
            table = np.loadtxt(
                body, delimiter=delimiter, comments="#", quotechar='"', ndmin=2, dtype=np.float64
            )
        except ValueError as e:
            _locate(body, head + 2, names, delimiter, name)
            raise CsvError(name, head + 2, 1, f"cannot read the rows as numbers: {e}") from None
    if table.size and table.shape[1] != len(names):
        _locate(body, head + 2, names, delimiter, name)
    table = table.reshape(-1, len(names))
    table.flags.writeable = False
    log = CsvLog(Path(path), names, table)
    _check_times(log.t, body, head + 2, names, delimiter, name)
    return log


def _decode(raw: bytes, name: str) -> str:
    nul = raw.find(b"\x00", 0, 1 << 16)
    if nul >= 0:
        line, col = _line_col(raw, nul)
        raise CsvError(
            name, line, col, "not a text file (a NUL byte): a .csv log is text, a header row then numbers"
        )
    try:
        return raw.decode("utf-8-sig").replace("\r\n", "\n").replace("\r", "\n")
    except UnicodeDecodeError as e:
        line, col = _line_col(raw, e.start)
        raise CsvError(
            name,
            line,
            col,
            f"byte 0x{raw[e.start]:02x} is not UTF-8 text: a binary file, or text in another encoding "
            "(save it as UTF-8)",
        ) from None


def _line_col(raw: bytes, pos: int) -> tuple[int, int]:
    line_start = raw.rfind(b"\n", 0, pos) + 1
    return raw.count(b"\n", 0, pos) + 1, pos - line_start + 1


def _split(row: str, delimiter: str | None) -> list[tuple[int, str]]:
    """Cells of one row with their 1-based start columns (quotes stripped)."""
    cells = []
    if delimiter is None:
        pos = 0
        for cell in row.split():
            pos = row.index(cell, pos)
            cells.append((pos + 1, cell))
            pos += len(cell)
        return cells
    pos = 0
    for cell in row.split(delimiter):
        lead = len(cell) - len(cell.lstrip())
        cells.append((pos + lead + 1, cell.strip().strip('"').strip("'")))
        pos += len(cell) + 1
    return cells


def _header(row: str, name: str, line: int) -> tuple[tuple[str, ...], str | None]:
    text = row.strip()
    offset = len(row) - len(row.lstrip())
    if text.startswith("#"):  # a commented header, as numpy.savetxt writes it
        offset += len(text) - len(text[1:].lstrip())
        text = text[1:].lstrip()
    delimiter = next((d for d in (",", ";", "\t") if d in text), None)
    cells = [(c + offset, s) for c, s in _split(text, delimiter)]
    names = [s for _, s in cells]
    for k, (col, s) in enumerate(cells):
        if not s:
            raise CsvError(name, line, col, "an empty column name in the header row")
        if s in names[:k]:
            raise CsvError(name, line, col, f"column '{s}' is named twice in the header row")
    if TIME not in names:
        looks = next((s for s in names if s in _TIME_LIKE or s.lower().startswith("time")), None)
        hint = (
            f"; if '{looks}' is the time in seconds, name it 't'"
            if looks
            else "; the header row names the columns, one of them 't' (seconds)"
        )
        raise CsvError(name, line, 1, f"no 't' column in the header row (columns: {', '.join(names)}){hint}")
    if len(names) < 2:
        raise CsvError(name, line, 1, "no data columns besides 't'")
    return tuple(names), delimiter


def _rows(body: list[str], first_line: int, delimiter: str | None):
    """(file line, cells) of each data row: blank lines and ``#`` comments skipped, as numpy does."""
    for k, row in enumerate(body):
        row = row.split("#", 1)[0]
        if row.strip():
            yield first_line + k, _split(row, delimiter)


def _locate(
    body: list[str], first_line: int, names: tuple[str, ...], delimiter: str | None, name: str
) -> None:
    """Raise :class:`CsvError` at the first row that numpy could not read (or return if none)."""
    for line, cells in _rows(body, first_line, delimiter):
        if len(cells) != len(names):
            col = cells[len(names)][0] if len(cells) > len(names) else (cells[-1][0] if cells else 1)
            raise CsvError(
                name,
                line,
                col,
                f"{len(cells)} values in this row, but the header names {len(names)} columns "
                f"({', '.join(names)})",
            )
        for (col, cell), column in zip(cells, names, strict=True):
            if not cell:
                raise CsvError(
                    name, line, col, f"an empty cell in column '{column}' (write nan for a missing value)"
                )
            try:
                float(cell)
            except ValueError:
                raise CsvError(name, line, col, f"not a number in column '{column}': '{cell}'") from None


def _check_times(
    t: np.ndarray, body: list[str], first_line: int, names: tuple[str, ...], delimiter: str | None, name: str
) -> None:
    bad = ~np.isfinite(t)
    back = np.flatnonzero(np.diff(t) < 0) + 1
    if not bad.any() and not len(back):
        return
    i = int(np.argmax(bad)) if bad.any() else int(back[0])
    if bad.any() and len(back):
        i = min(i, int(back[0]))
    line, cells = next(r for k, r in enumerate(_rows(body, first_line, delimiter)) if k == i)
    col = cells[names.index(TIME)][0]
    if not np.isfinite(t[i]):
        raise CsvError(
            name, line, col, f"time '{cells[names.index(TIME)][1]}' in column 't' is not a finite number"
        )
    raise CsvError(
        name,
        line,
        col,
        f"time goes back: t = {t[i]:.9g} s after {t[i - 1]:.9g} s on the row before (times must not decrease)",
    )
