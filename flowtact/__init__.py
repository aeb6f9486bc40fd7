"""flowtact: YAML graphs of reusable streaming blocks for tactile sensing and haptics."""

from flowtact.block import BadDataError, Block, Example, Port, Source, SpecError, screen_nonfinite
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
    "param",
    "screen_nonfinite",
]
