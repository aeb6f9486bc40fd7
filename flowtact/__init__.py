"""flowtact: YAML graphs of reusable streaming blocks for tactile sensing and haptics."""

from flowtact.block import (
    BadDataError,
    Block,
    Example,
    Port,
    Source,
    SpecError,
    nonfinite_counter_docs,
    screen_nonfinite,
)
from flowtact.chunk import Chunk, StreamSpec, concat
from flowtact.params import Config, ConfigError, param

__version__ = "0.1.0"

__all__ = [
    "BadDataError",
    "Block",
    "Chunk",
    "Config",
    "ConfigError",
    "Example",
    "Port",
    "Source",
    "SpecError",
    "StreamSpec",
    "__version__",
    "concat",
    "nonfinite_counter_docs",
    "param",
    "screen_nonfinite",
]
