"""flowtact: YAML graphs of reusable streaming blocks for tactile sensing and haptics."""

from flowtact.block import (
    BadDataConfig,
    BadDataError,
    BadDataPolicy,
    Block,
    Example,
    Port,
    Source,
    SpecError,
    nonfinite_counter_docs,
    screen_nonfinite,
)
from flowtact.chunk import Chunk, StreamSpec, concat
from flowtact.errors import FlowtactError
from flowtact.params import Config, ConfigError, param

__version__ = "0.1.0"


def sweep(graph, **kwargs):  # type: ignore[no-untyped-def]
    """Run a graph over a parameter grid and recordings; a pandas DataFrame, one row per run
    (:func:`flowtact.sweeps.api.sweep`; needs ``pip install "flowtact[sweep]"``)."""
    from flowtact.sweeps.api import sweep as run_sweep

    return run_sweep(graph, **kwargs)


__all__ = [
    "BadDataConfig",
    "BadDataError",
    "BadDataPolicy",
    "Block",
    "Chunk",
    "Config",
    "ConfigError",
    "Example",
    "FlowtactError",
    "Port",
    "Source",
    "SpecError",
    "StreamSpec",
    "__version__",
    "concat",
    "nonfinite_counter_docs",
    "param",
    "screen_nonfinite",
    "sweep",
]
