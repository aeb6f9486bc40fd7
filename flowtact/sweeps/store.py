"""A sweep's result table on disk (Parquet), the setup it records, and resuming from it.

Rows are rewritten atomically (a temporary file renamed over the old one), so an interrupted
sweep, or one killed between writes, leaves the last complete table. The table's Parquet metadata
records the sweep's *setup* (the graph's hash and every fixed setting, :func:`setup_differences`
compares two) and each row a ``setup`` hash; resume refuses a table made by another setup, keeps
the rows whose status is ``ok`` and runs every other row again.

A table may come from someone else: it is read only if it is a regular file within
:data:`MAX_TABLE_BYTES` on disk and, as its footer declares, uncompressed, with at most
:data:`MAX_TABLE_ROWS` rows, :data:`MAX_TABLE_COLUMNS` columns and :data:`MAX_TABLE_CELLS` cells
(checked before reading rows); its setup is compared, from the footer, before its rows are read.
"""

from __future__ import annotations

import json
import math
import os
import stat
import tempfile
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any

from flowtact.errors import SweepSpecError
from flowtact.sweeps.grid import MAX_ROWS

__all__ = [
    "FIRST_COLUMNS",
    "MAX_TABLE_BYTES",
    "MAX_TABLE_CELLS",
    "MAX_TABLE_COLUMNS",
    "MAX_TABLE_ROWS",
    "SETUP_KEY",
    "check_writable",
    "done_rows",
    "read_setup",
    "setup_differences",
    "to_frame",
    "write_table",
]

FIRST_COLUMNS = ("key", "status", "error", "seed", "setup", "provenance", "run_s", "duration_s")
SETUP_KEY = b"flowtact.sweep.setup"
"""The Parquet metadata key holding the sweep's setup (JSON)."""
MAX_TABLE_BYTES = 256 << 20
"""Largest table resumed from (256 MiB): on disk, uncompressed as its footer declares it, and
decoded (a text repeated in every row counted once per row)."""
MAX_TABLE_ROWS = MAX_ROWS
"""Most rows a resumed table may hold: the most a sweep can have."""
MAX_TABLE_COLUMNS = 10_000
"""Most columns a resumed table may hold (parameters, recordings, bookkeeping and metrics)."""
MAX_TABLE_CELLS = 5_000_000
"""Most cells (rows × columns) a resumed table may hold: each becomes a Python value of a row."""


def to_frame(rows: Sequence[dict[str, Any]], first: Sequence[str] = ()) -> Any:
    """Rows as a DataFrame: ``first`` columns (parameters, recordings), the bookkeeping columns,
    then the metrics in order of appearance. Columns holding values of mixed types (``1`` and
    ``"a"``) are stored as their YAML text so Parquet can hold them."""
    import pandas as pd

    df = pd.DataFrame(list(rows))
    order = [c for c in (*first, *FIRST_COLUMNS) if c in df.columns]
    df = df[order + [c for c in df.columns if c not in order]]
    for col in df.columns:
        if pd.api.types.is_numeric_dtype(df[col]) or pd.api.types.is_bool_dtype(df[col]):
            continue
        kinds = {type(v) for v in df[col] if v is not None and v == v}
        if len(kinds) > 1 or kinds & {list, dict, tuple}:
            from flowtact.sweeps.grid import override_text

            df[col] = [None if v is None else override_text(v) for v in df[col]]
    return df


def check_writable(out: str | Path) -> None:
    """Raise :class:`SweepSpecError` unless the table can be written at ``out``: its folder exists
    and takes a new file (one is made and removed), and ``out`` is not a folder or a special file.
    Called before the first run, so no run's row is lost to a bad ``--out``."""
    p = Path(out)
    folder = p.parent if str(p.parent) else Path(".")
    if p.is_dir():
        raise SweepSpecError(f"--out {p}: is a folder; give a file name (FILE.parquet)")
    if p.exists() and not stat.S_ISREG(p.stat().st_mode):
        raise SweepSpecError(f"--out {p}: is not a regular file")
    if not folder.is_dir():
        raise SweepSpecError(f"--out {p}: the folder {folder} does not exist")
    try:
        fd, tmp = tempfile.mkstemp(prefix=f".{p.name}.", suffix=".check", dir=folder)
        os.close(fd)
        os.unlink(tmp)
    except OSError as e:
        raise SweepSpecError(f"--out {p}: cannot write in {folder}: {e.strerror or e}") from None


def write_table(df: Any, out: str | Path, setup: Mapping[str, Any] | None = None) -> None:
    """Write ``df`` to ``out`` (Parquet) atomically, with ``setup`` in the file's metadata."""
    import pyarrow as pa
    import pyarrow.parquet as pq

    out = Path(out)
    table = pa.Table.from_pandas(df, preserve_index=False)
    if setup is not None:
        meta = dict(table.schema.metadata or {})
        meta[SETUP_KEY] = json.dumps(dict(setup), sort_keys=True).encode()
        table = table.replace_schema_metadata(meta)
    fd, tmp = tempfile.mkstemp(prefix=f".{out.name}.", suffix=".tmp", dir=out.parent)
    os.close(fd)
    try:
        pq.write_table(table, tmp)
        os.replace(tmp, out)
    finally:
        Path(tmp).unlink(missing_ok=True)


def _footer(out: Path) -> Any:
    """The table's Parquet footer, after checking the file is a regular one within budget."""
    import pyarrow.parquet as pq

    st = out.stat()
    if not stat.S_ISREG(st.st_mode):
        raise SweepSpecError(f"--out {out}: cannot resume from it, not a regular file")
    if st.st_size > MAX_TABLE_BYTES:
        raise SweepSpecError(f"--out {out}: cannot resume from it, {st.st_size:,} bytes "
                             f"(at most {MAX_TABLE_BYTES:,}); use another --out or --fresh")  # fmt: skip
    try:
        meta = pq.read_metadata(out)
    except Exception as e:  # noqa: BLE001 - pyarrow raises several types for a file that is not Parquet
        raise SweepSpecError(f"--out {out}: cannot resume from it, not a readable Parquet table "
                             f"({_short(e)}); use another --out or --fresh") from None  # fmt: skip
    size = sum(meta.row_group(i).total_byte_size for i in range(meta.num_row_groups))
    if meta.num_rows > MAX_TABLE_ROWS or meta.num_columns > MAX_TABLE_COLUMNS or size > MAX_TABLE_BYTES:
        raise SweepSpecError(
            f"--out {out}: cannot resume from it, it declares {meta.num_rows:,} rows, {meta.num_columns:,} "
            f"columns, {size:,} bytes (at most {MAX_TABLE_ROWS:,}, {MAX_TABLE_COLUMNS:,}, {MAX_TABLE_BYTES:,})"
        )
    return meta


def _short(e: BaseException) -> str:
    text = str(e).strip().splitlines()[0] if str(e).strip() else type(e).__name__
    return _shown(text)


def read_setup(out: str | Path) -> dict[str, Any] | None:
    """The setup recorded in an existing table, or None (none recorded, or not readable as JSON)."""
    meta = _footer(Path(out)).metadata or {}
    try:
        setup = json.loads(meta[SETUP_KEY])
    except (KeyError, ValueError):
        return None
    return setup if isinstance(setup, dict) else None


def done_rows(out: str | Path) -> list[dict[str, Any]]:
    """Rows of an existing table (none if ``out`` does not exist); rows are plain dicts."""

    out = Path(out)
    if not out.exists():
        return []
    meta = _footer(out)
    if meta.num_rows * meta.num_columns > MAX_TABLE_CELLS:
        raise SweepSpecError(f"--out {out}: cannot resume from it, {meta.num_rows:,} rows × {meta.num_columns:,} "
                             f"columns is over {MAX_TABLE_CELLS:,} cells")  # fmt: skip
    try:
        df = _read_frame(out)
    except SweepSpecError:
        raise
    except Exception as e:  # noqa: BLE001 - pyarrow raises several types for a file that is not Parquet
        raise SweepSpecError(f"--out {out}: cannot resume from it, not a readable Parquet table "
                             f"({_short(e)}); use another --out or --fresh") from None  # fmt: skip
    if "key" not in df.columns or "status" not in df.columns:
        raise SweepSpecError(f"--out {out}: cannot resume from it, not a flowtact sweep table "
                             "(no key/status columns); use another --out or --fresh")  # fmt: skip
    return [{k: _plain(v) for k, v in r.items() if not _missing(v)} for r in df.to_dict(orient="records")]


def _read_frame(out: Path) -> Any:
    """The table as a DataFrame, text columns kept dictionary-encoded (pandas categoricals), so a
    value repeated in every row is held once, as the file holds it, not once per row."""
    import pyarrow as pa
    import pyarrow.parquet as pq

    schema = pq.read_schema(out)
    text = [f.name for f in schema if pa.types.is_string(f.type) or pa.types.is_large_string(f.type)]
    table = pq.read_table(out, read_dictionary=text)
    if (size := _decoded_bytes(table)) > MAX_TABLE_BYTES:
        raise SweepSpecError(f"--out {out}: cannot resume from it, its rows hold {size:,} bytes "
                             f"(at most {MAX_TABLE_BYTES:,})")  # fmt: skip
    return table.to_pandas()


def _decoded_bytes(table: Any) -> int:
    """Bytes the table's values take once decoded: a dictionary-encoded text column's values
    counted once per row that refers to them (what pandas would hold), other columns as Arrow holds them."""
    import pyarrow as pa
    import pyarrow.compute as pc

    total = 0
    for column in table.columns:
        for chunk in column.chunks:
            if pa.types.is_dictionary(chunk.type):
                lengths = pc.binary_length(chunk.dictionary)
                total += int(pc.sum(pc.take(lengths, chunk.indices)).as_py() or 0) + 8 * len(chunk)
            else:
                total += chunk.nbytes
    return total


def setup_differences(old: Mapping[str, Any], new: Mapping[str, Any]) -> list[str]:
    """What differs between two setups, in words (``--duration 2 vs 1``, ``--set adds [a.b=1]``),
    the table's value first; empty when equal."""
    out = []
    for name in sorted(set(old) | set(new)):
        a, b = old.get(name), new.get(name)
        if a == b:
            continue
        label = SETUP_LABELS.get(name, name)
        if name == "graph":
            out.append("the graph differs")
        elif isinstance(a, list) and isinstance(b, list):
            gone, new_ = [x for x in a if x not in b], [x for x in b if x not in a]
            said = [f"adds {_shown(new_)}"] * bool(new_) + [f"drops {_shown(gone)}"] * bool(gone)
            out.append(f"{label} {' and '.join(said) or 'has the same values in another order'}")
        else:
            out.append(f"{label} {_shown(a)} vs {_shown(b)}")
    return out


SHOWN_CHARS = 100
"""Longest text shown of one setting in a refusal (a table's metadata may hold anything)."""
SETUP_LABELS = {
    "duration_s": "--duration",
    "set": "--set",
    "metrics": "--metrics",
    "rmse": "--rmse",
    "flowtact": "flowtact",
    "seeds": "seed policy",
}


def _shown(v: Any) -> str:
    """A setting as text, short and with control characters escaped (a table's metadata is data)."""
    if v is None:
        return "(not given)"
    if v == []:
        return "(none)"
    text = "[" + ", ".join(map(str, v)) + "]" if isinstance(v, (list, tuple)) else str(v)
    text = "".join(c if c.isprintable() else c.encode("unicode_escape").decode("ascii") for c in text)
    return text if len(text) <= SHOWN_CHARS else text[: SHOWN_CHARS - 3] + "..."


def _missing(v: Any) -> bool:
    return v is None or (isinstance(v, float) and math.isnan(v))


def _plain(v: Any) -> Any:
    """A numpy scalar as the Python value it holds (bit for bit)."""
    return v.item() if hasattr(v, "item") and not isinstance(v, (list, dict, str)) else v
