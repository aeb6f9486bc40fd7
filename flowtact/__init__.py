"""flowtact: YAML graphs of reusable streaming blocks for tactile sensing and haptics."""

from typing import TYPE_CHECKING, Any

from flowtact import errors
from flowtact.block import (
    BadDataConfig,
    BadDataPolicy,
    Block,
    Example,
    Port,
    Source,
    nonfinite_counter_docs,
    screen_nonfinite,
)
from flowtact.chunk import Chunk, StreamSpec, concat
from flowtact.errors import *  # noqa: F403 — errors.__all__, exported below
from flowtact.params import Config, param
from flowtact.version import __version__

if TYPE_CHECKING:
    from flowtact.running.builder import GraphBuilder
    from flowtact.running.from_python import run
    from flowtact.running.results import RunResult, Stream, read_streams

_LAZY = {
    "GraphBuilder": "flowtact.running.builder",
    "run": "flowtact.running.from_python",
    "RunResult": "flowtact.running.results",
    "Stream": "flowtact.running.results",
    "read_streams": "flowtact.running.results",
}
"""Runs from Python (docs/python.md), imported on first use: ``import flowtact`` stays light."""


def __getattr__(name: str) -> Any:
    if name in _LAZY:
        import importlib

        return getattr(importlib.import_module(_LAZY[name]), name)
    raise AttributeError(f"module 'flowtact' has no attribute {name!r}")


def sweep(graph, **kwargs):  # type: ignore[no-untyped-def]
    """Run a graph over a parameter grid and recordings; a pandas DataFrame, one row per run
    (:func:`flowtact.sweeps.api.sweep`; needs ``pip install "flowtact[sweep]"``)."""
    from flowtact.sweeps.api import sweep as run_sweep

    return run_sweep(graph, **kwargs)


__all__ = [
    "BadDataConfig",
    "BadDataPolicy",
    "Block",
    "Chunk",
    "Config",
    "Example",
    "GraphBuilder",
    "Port",
    "RunResult",
    "Source",
    "Stream",
    "StreamSpec",
    "__version__",
    "concat",
    "nonfinite_counter_docs",
    "param",
    "read_streams",
    "run",
    "screen_nonfinite",
    "sweep",
]
__all__ += errors.__all__  # every public error (flowtact.errors keeps the one list of them)
