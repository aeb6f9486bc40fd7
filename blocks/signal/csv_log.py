"""Read a CSV sensor log (a header row naming the columns, one of them ``t`` in seconds, then numbers)
into a float64 table, refusing a bad file with the line and column of the first problem.

Accepted: UTF-8 text (a byte-order mark is fine), columns separated by commas, semicolons, tabs or
spaces (whichever the header uses), ``#`` comments and blank lines, ``nan``/``inf`` in data columns.
Refused, each with ``file:line:col``: a binary or non-UTF-8 file, a header without ``t``, duplicate
or empty column names, a row with too few or too many values, a cell that is not a number, a time
that is not finite or that goes back; and, before they are read (:mod:`.replay_limits`,
:func:`flowtact.inputs.bounded_files.open_regular`), anything but a regular file, a file over ``MAX_TEXT_BYTES``, a line over ``MAX_LINE_BYTES``, a header of
more than ``MAX_COLUMNS`` columns. The text is streamed: checked a block at a time, then parsed
by numpy line by line, so memory is the table plus a block.
"""

from __future__ import annotations

import codecs
import functools
import io
import os
import warnings
from collections.abc import Iterable, Iterator
from dataclasses import dataclass
from pathlib import Path
from typing import BinaryIO

import numpy as np

import flowtact.api as ft
from flowtact.blocks.signal.replay_limits import MAX_COLUMNS, MAX_LINE_BYTES, MAX_TEXT_BYTES, listing
from flowtact.errors import FileRefused
from flowtact.inputs.bounded_files import open_regular, refusal

__all__ = ["CsvError", "CsvLog", "read_csv_log", "row_place"]

_BLOCK = 1 << 20  # bytes read at a time while checking the text

TIME = "t"
#: Header names that look like a time column but are not called ``t``: named in the hint.
_TIME_LIKE = ("time", "time_s", "t_s", "timestamp", "times", "T", "Time", "TIME", "seconds", "sec")


class CsvError(ft.FlowtactError, ValueError):
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
    body_line: int = 2  # the file line after the header: where data rows start
    delimiter: str | None = ","

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
    """Parse ``path``; raise :class:`CsvError` at the first problem (cached per file version).

    Bounded before anything is read: a regular file only, at most :data:`MAX_TEXT_BYTES`, lines of
    at most :data:`MAX_LINE_BYTES`, at most :data:`MAX_COLUMNS` columns; the text is streamed.
    """
    with _open(path) as f:
        st = os.fstat(f.fileno())
    return _read(str(path), st.st_mtime_ns, st.st_size)


def _open(path: str | Path) -> BinaryIO:
    """``path`` opened if a regular file, else :class:`CsvError` at its first line."""
    try:
        return open_regular(path)
    except OSError as e:
        raise CsvError(display(path), 1, 1, refusal(path, e).reason) from None
    except FileRefused as e:
        raise CsvError(display(path), 1, 1, e.reason) from None


@functools.lru_cache(maxsize=4)
def _read(path: str, _mtime_ns: int, _size: int) -> CsvLog:
    """One parse per file version: the replay of each port of a node reads the same table."""
    name = display(path)
    with _open(path) as raw:
        size = os.fstat(raw.fileno()).st_size
        if size > MAX_TEXT_BYTES:
            raise CsvError(
                name,
                1,
                1,
                f"{ft.format_bytes(size)}: larger than the {ft.format_bytes(MAX_TEXT_BYTES)} a .csv log may be "
                "(its table is held in memory); split it, or record to .h5",
            )
        _scan(raw, name)
        raw.seek(0)
        text = io.TextIOWrapper(raw, encoding="utf-8-sig", newline=None)
        head, row = _first_row(text)
        if row is None:
            raise CsvError(
                name, 1, 1, "the file is empty; a header row naming the columns (one of them 't') comes first"
            )
        names, delimiter = _header(row, name, head)
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")  # a header-only file is fine: zero rows
            try:
                table = np.loadtxt(
                    text, delimiter=delimiter, comments="#", quotechar='"', ndmin=2, dtype=np.float64
                )
            except ValueError as e:
                _locate(path, head + 1, names, delimiter, name)
                raise CsvError(name, head + 1, 1, f"cannot read the rows as numbers: {e}") from None
    if table.size and table.shape[1] != len(names):
        _locate(path, head + 1, names, delimiter, name)
    table = table.reshape(-1, len(names))
    table.flags.writeable = False
    log = CsvLog(Path(path), names, table, head + 1, delimiter)
    _check_times(log, name)
    return log


def _first_row(text: io.TextIOWrapper) -> tuple[int, str | None]:
    """(1-based line, text) of the first non-blank line (the header), or (0, None) if none."""
    for k, row in enumerate(text, 1):
        if row.strip():
            return k, row.rstrip("\n")
    return 0, None


def _scan(raw: BinaryIO, name: str) -> None:
    """Stream the file once, a block at a time, refusing a NUL byte, bytes that are not UTF-8 and
    a line longer than :data:`MAX_LINE_BYTES`, each at its line and column."""
    decoder = codecs.getincrementaldecoder("utf-8")()
    lines_before = 0  # newlines before this block
    col_before = 0  # bytes of the current line before this block
    run = 0  # bytes of the current line so far (\r or \n end a line)
    while block := raw.read(_BLOCK):
        nul = block.find(b"\x00")
        if nul >= 0:
            line, col = _place(block, nul, lines_before, col_before)
            raise CsvError(
                name, line, col, "not a text file (a NUL byte): a .csv log is text, a header row then numbers"
            )
        buffered = decoder.getstate()[0]  # the start of a character cut by the last block
        try:
            decoder.decode(block)
        except UnicodeDecodeError as e:
            at = max(e.start - len(buffered), 0)
            line, col = _place(block, at, lines_before, col_before)
            bad = (buffered + block[: at + 1])[e.start]
            raise CsvError(
                name,
                line,
                col,
                f"byte 0x{bad:02x} is not UTF-8 text: a binary file, or text in another encoding "
                "(save it as UTF-8)",
            ) from None
        run = _check_lines(block, run, lines_before, col_before, name)
        lines_before += block.count(b"\n")
        last = block.rfind(b"\n")
        col_before = col_before + len(block) if last < 0 else len(block) - last - 1
    cut = len(decoder.getstate()[0])
    if cut:
        raise CsvError(name, lines_before + 1, col_before - cut + 1, "the file ends inside a UTF-8 character")


def _place(block: bytes, at: int, lines_before: int, col_before: int) -> tuple[int, int]:
    """1-based (line, column) of byte ``at`` of ``block``, given what came before it."""
    newlines = block.count(b"\n", 0, at)
    if not newlines:
        return lines_before + 1, col_before + at + 1
    return lines_before + newlines + 1, at - block.rfind(b"\n", 0, at)


def _check_lines(block: bytes, run: int, lines_before: int, col_before: int, name: str) -> int:
    """Refuse a line of ``block`` longer than :data:`MAX_LINE_BYTES` (vectorised: a file of empty
    lines costs no Python per line); return the length of the line still open at its end."""
    a = np.frombuffer(block, np.uint8)
    ends = np.flatnonzero((a == 10) | (a == 13))
    if not len(ends):
        lengths, starts = np.array([run + len(block)]), np.array([0])
    else:
        lengths = np.diff(ends, prepend=-1 - run, append=len(block)) - 1
        starts = np.concatenate(([0], ends + 1))
    over = np.flatnonzero(lengths > MAX_LINE_BYTES)
    if len(over):
        line, _ = _place(block, int(min(starts[over[0]], len(block) - 1)), lines_before, col_before)
        raise CsvError(
            name,
            line,
            1,
            f"a line longer than {ft.format_bytes(MAX_LINE_BYTES)} (a .csv row is at most "
            f"{MAX_LINE_BYTES} bytes): not a sensor log",
        )
    return int(lengths[-1])


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
    """Column names and delimiter of the header row: linear in its length, at most
    :data:`MAX_COLUMNS` names."""
    text = row.strip()
    offset = len(row) - len(row.lstrip())
    if text.startswith("#"):  # a commented header, as numpy.savetxt writes it
        offset += len(text) - len(text[1:].lstrip())
        text = text[1:].lstrip()
    delimiter = next((d for d in (",", ";", "\t") if d in text), None)
    count = text.count(delimiter) + 1 if delimiter else len(text.split())
    if count > MAX_COLUMNS:
        raise CsvError(
            name, line, 1, f"{count} columns in the header row; a .csv log may have at most {MAX_COLUMNS}"
        )
    cells = [(c + offset, s) for c, s in _split(text, delimiter)]
    names = [s for _, s in cells]
    seen: set[str] = set()
    for col, s in cells:
        if not s:
            raise CsvError(name, line, col, "an empty column name in the header row")
        if s in seen:
            raise CsvError(name, line, col, f"column '{s}' is named twice in the header row")
        seen.add(s)
    if TIME not in seen:
        looks = next((s for s in names if s in _TIME_LIKE or s.lower().startswith("time")), None)
        hint = (
            f"; if '{looks}' is the time in seconds, name it 't'"
            if looks
            else "; the header row names the columns, one of them 't' (seconds)"
        )
        raise CsvError(name, line, 1, f"no 't' column in the header row (columns: {listing(names)}){hint}")
    if len(names) < 2:
        raise CsvError(name, line, 1, "no data columns besides 't'")
    return tuple(names), delimiter


def _body(path: str, first_line: int) -> Iterator[str]:
    """The lines of ``path`` from line ``first_line`` on (streamed; the file was checked by
    :func:`_scan`, so every line is bounded)."""
    with open_regular(path) as raw, io.TextIOWrapper(raw, encoding="utf-8-sig", newline=None) as text:
        for k, row in enumerate(text, 1):
            if k >= first_line:
                yield row.rstrip("\n")


def _rows(body: Iterable[str], first_line: int, delimiter: str | None) -> Iterator[tuple[int, list]]:
    """(file line, cells) of each data row: blank lines and ``#`` comments skipped, as numpy does."""
    for k, row in enumerate(body):
        row = row.split("#", 1)[0]
        if row.strip():
            yield first_line + k, _split(row, delimiter)


def _locate(path: str, first_line: int, names: tuple[str, ...], delimiter: str | None, name: str) -> None:
    """Raise :class:`CsvError` at the first row that numpy could not read (or return if none)."""
    for line, cells in _rows(_body(path, first_line), first_line, delimiter):
        if len(cells) != len(names):
            col = cells[len(names)][0] if len(cells) > len(names) else (cells[-1][0] if cells else 1)
            raise CsvError(
                name,
                line,
                col,
                f"{len(cells)} values in this row, but the header names {len(names)} columns "
                f"({listing(names)})",
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


def row_place(log: CsvLog, i: int) -> tuple[int, int, str]:
    """(line, column, text) of the time stamp of data row ``i`` of ``log``, for a located error."""
    rows = _rows(_body(str(log.path), log.body_line), log.body_line, log.delimiter)
    line, cells = next(r for k, r in enumerate(rows) if k == i)
    col, text = cells[log.names.index(TIME)]
    return line, col, text


def _check_times(log: CsvLog, name: str) -> None:
    t = log.t
    bad = ~np.isfinite(t)
    back = np.flatnonzero(np.diff(t) < 0) + 1
    if not bad.any() and not len(back):
        return
    i = int(np.argmax(bad)) if bad.any() else int(back[0])
    if bad.any() and len(back):
        i = min(i, int(back[0]))
    line, col, text = row_place(log, i)
    if not np.isfinite(t[i]):
        raise CsvError(name, line, col, f"time '{text}' in column 't' is not a finite number")
    raise CsvError(
        name,
        line,
        col,
        f"time goes back: t = {t[i]:.9g} s after {t[i - 1]:.9g} s on the row before (times must not decrease)",
    )
