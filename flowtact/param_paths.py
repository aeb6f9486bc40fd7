"""Relative file names in block parameters, made absolute against the place they were written.

A parameter declared with ``param(..., path=True)`` names a file or folder (a replay's recording, a
camera's video file or image folder, a model checkpoint). Written in a graph file, a relative name
means "beside the graph file"; given on the command line (``--set``, ``--replay``) it means "from
the working directory". Resolving it once, when the graph is loaded, keeps that meaning wherever the
block later runs (a worker process) and stores the absolute name in a recording's provenance, so
``flowtact run REC.h5`` finds the same file from any folder.
"""

from __future__ import annotations

import dataclasses
import os
from collections.abc import Mapping
from pathlib import Path
from typing import Any

__all__ = ["path_fields", "resolve_path", "resolve_paths"]


def path_fields(config_cls: type) -> frozenset[str]:
    """Names of the fields of ``config_cls`` declared with ``param(..., path=True)``."""
    return frozenset(f.name for f in dataclasses.fields(config_cls) if f.metadata.get("path"))


def resolve_path(text: str, base: str | Path) -> str:
    """``text`` as an absolute name: ``~`` expanded, a relative name joined to ``base``.

    URLs (``rtsp://...``) and empty strings are left alone: they are not names of local files.
    """
    if not text or "://" in text:
        return text
    p = Path(text).expanduser()
    return os.path.abspath(p if p.is_absolute() else Path(base) / p)


def _resolve(value: Any, base: str | Path) -> Any:
    if isinstance(value, str):
        return resolve_path(value, base)
    if isinstance(value, (list, tuple)):  # e.g. camera devices: indices stay, names resolve
        return type(value)(_resolve(v, base) for v in value)
    return value  # None, a device index


def resolve_paths(config_cls: type, params: Mapping[str, Any], base: str | Path) -> dict[str, Any]:
    """A copy of ``params`` with the values of path fields resolved against ``base``."""
    fields = path_fields(config_cls)
    return {k: (_resolve(v, base) if k in fields else v) for k, v in params.items()}
