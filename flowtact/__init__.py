"""flowtact: YAML graphs of reusable streaming blocks for tactile sensing and haptics."""

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
    "Port",
    "Source",
    "StreamSpec",
    "__version__",
    "concat",
    "nonfinite_counter_docs",
    "param",
    "screen_nonfinite",
    "sweep",
]
__all__ += errors.__all__  # every public error (flowtact.errors keeps the one list of them)
