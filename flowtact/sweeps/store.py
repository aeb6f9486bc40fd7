"""A sweep's result table on disk (Parquet) and resuming from it.

Rows are rewritten atomically (a temporary file renamed over the old one), so an interrupted
sweep, or one killed between writes, leaves the last complete table. Resume keeps the rows whose
status is ``ok`` and runs every other row again.
"""

from __future__ import annotations

import math
import os
from collections.abc import Sequence
from pathlib import Path
from typing import Any

__all__ = ["FIRST_COLUMNS", "done_rows", "to_frame", "write_table"]

FIRST_COLUMNS = ("key", "status", "error", "seed", "provenance", "run_s", "duration_s")


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


def write_table(df: Any, out: str | Path) -> None:
    """Write ``df`` to ``out`` (Parquet) atomically."""
    out = Path(out)
    tmp = out.with_name(f".{out.name}.{os.getpid()}.tmp")
    try:
        df.to_parquet(tmp, index=False)
        os.replace(tmp, out)
    finally:
        tmp.unlink(missing_ok=True)


def done_rows(out: str | Path) -> list[dict[str, Any]]:
    """Rows of an existing table (none if ``out`` does not exist); rows are plain dicts."""
    import pandas as pd

    out = Path(out)
    if not out.exists():
        return []
    try:
        df = pd.read_parquet(out)
    except Exception as e:  # noqa: BLE001 - pyarrow raises several types for a file that is not Parquet
        raise OSError(f"{out}: cannot resume from it, not a readable Parquet table ({e})") from None
    if "key" not in df.columns or "status" not in df.columns:
        raise OSError(f"{out}: cannot resume from it, not a flowtact sweep table (no key/status columns)")
    return [{k: _plain(v) for k, v in r.items() if not _missing(v)} for r in df.to_dict(orient="records")]


def _missing(v: Any) -> bool:
    return v is None or (isinstance(v, float) and math.isnan(v))


def _plain(v: Any) -> Any:
    """A numpy scalar as the Python value it holds (bit for bit)."""
    return v.item() if hasattr(v, "item") and not isinstance(v, (list, dict, str)) else v
