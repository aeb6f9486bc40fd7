"""Relative file names in block parameters, made absolute against the place they were written.

A parameter declared with ``param(..., path=True)`` names a file or folder (a replay's recording, a
camera's video file or image folder, a model checkpoint). Written in a graph file, a relative name
means "beside the graph file"; given on the command line (``--set``, ``--replay``) it means "from
the working directory". Resolving it once, when the graph is loaded, keeps that meaning wherever the
block later runs (a worker process) and stores the absolute name in a recording's provenance, so
``flowtact run REC.h5`` finds the same file from any folder.

A relative name in a graph file is joined to the graph file's *real* folder (symlinks resolved), so
a graph reached through a symlinked folder still finds the files beside its original.

Files shipped inside an installed package are named ``pkg:PACKAGE/FILE`` (for example
``pkg:flowtact.blocks.braille.models/braille_first.npz``): found wherever flowtact is installed
(source tree, wheel, a copy of the graph in another folder). Only flowtact's own packages may be
named (finding a package's folder imports it, and importing runs code), and FILE stays inside the
package (no ``..``, no absolute name).
"""

from __future__ import annotations

import dataclasses
import importlib.resources
import os
import re
from collections.abc import Mapping
from pathlib import Path
from typing import Any

__all__ = [
    "PKG_PREFIX",
    "graph_folder",
    "package_file",
    "path_fields",
    "resolve_path",
    "resolve_paths",
    "resolve_value",
]

#: Prefix of a file shipped inside a package: ``pkg:PACKAGE/FILE``.
PKG_PREFIX = "pkg:"
#: The packages ``pkg:`` may name: flowtact's own (importing them runs only flowtact's code).
PKG_ROOTS = ("flowtact",)
_PKG_RE = re.compile(r"^[A-Za-z_]\w*(\.[A-Za-z_]\w*)*$")


def path_fields(config_cls: type) -> frozenset[str]:
    """Names of the fields of ``config_cls`` declared with ``param(..., path=True)``."""
    return frozenset(f.name for f in dataclasses.fields(config_cls) if f.metadata.get("path"))


def graph_folder(graph_path: str | Path) -> Path:
    """The folder relative names in a graph file are read from: the file's real folder."""
    return Path(os.path.realpath(graph_path)).parent


def package_file(text: str) -> str:
    """The absolute name of ``pkg:PACKAGE/FILE``; :class:`ValueError` (one line) when it cannot be.

    The file need not exist (the block that opens it says so, as for any name).
    """
    package, slash, name = text[len(PKG_PREFIX) :].partition("/")
    parts = Path(name).parts
    if not slash or not name or Path(name).is_absolute() or ".." in parts or "\\" in name:
        raise ValueError(f"'{text}': expected pkg:PACKAGE/FILE, FILE inside the package")
    if not _PKG_RE.match(package) or not any(package == r or package.startswith(r + ".") for r in PKG_ROOTS):
        raise ValueError(f"'{text}': pkg: names a package of flowtact's own ({', '.join(PKG_ROOTS)}.*)")
    try:
        root = importlib.resources.files(package)
    except (ModuleNotFoundError, TypeError):
        raise ValueError(f"'{text}': no installed package '{package}'") from None
    return os.path.abspath(str(root.joinpath(*parts)))


def resolve_path(text: str, base: str | Path) -> str:
    """``text`` as an absolute name: ``~`` expanded, a relative name joined to ``base``,
    ``pkg:PACKAGE/FILE`` found inside the installed package (:func:`package_file`).

    URLs (``rtsp://...``) and empty strings are left alone: they are not names of local files.
    """
    if not text or "://" in text:
        return text
    if text.startswith(PKG_PREFIX):
        return package_file(text)
    p = Path(text).expanduser()
    return os.path.abspath(p if p.is_absolute() else Path(base) / p)


def resolve_value(value: Any, base: str | Path) -> Any:
    """A path field's value resolved: a name (:func:`resolve_path`), or each name of a list."""
    if isinstance(value, str):
        return resolve_path(value, base)
    if isinstance(value, (list, tuple)):  # e.g. camera devices: indices stay, names resolve
        return type(value)(resolve_value(v, base) for v in value)
    return value  # None, a device index


def resolve_paths(config_cls: type, params: Mapping[str, Any], base: str | Path) -> dict[str, Any]:
    """A copy of ``params`` with the values of path fields resolved against ``base``."""
    fields = path_fields(config_cls)
    return {k: (resolve_value(v, base) if k in fields else v) for k, v in params.items()}
