"""Everything a block author uses, in one import: ``import flowtact.api as ft``.

A block module writes ``class Lowpass(ft.Block)``, ``inputs = {"x": ft.Port(...)}``,
``ft.param(...)``, ``ft.Chunk(...)``: one line of imports instead of a list from five framework
modules, and a reader sees at a glance which names the framework provides. The names are the
framework's own (this module only gathers them), so ``flowtact.block.Block is ft.Block``.
"""

from __future__ import annotations

from flowtact.block import (
    BadDataConfig,
    BadDataPolicy,
    Block,
    Example,
    Port,
    Source,
    example_folder,
    nonfinite_counter_docs,
    screen_nonfinite,
)
from flowtact.chunk import Chunk, StreamSpec, concat
from flowtact.errors import BadDataError, ConfigError, FlowtactError, MisalignedError, SpecError
from flowtact.finite import all_finite
from flowtact.inputs.limits import (
    MAX_SEED,
    MAX_TICK_S,
    NOMINAL_FRAME_BYTES,
    NOMINAL_RATE_HZ,
    STATE_BUDGET_BYTES,
    format_bytes,
)
from flowtact.params import Config, param
from flowtact.streams.align import Aligner, screen_aligned

__all__ = [
    "MAX_SEED",
    "MAX_TICK_S",
    "NOMINAL_FRAME_BYTES",
    "NOMINAL_RATE_HZ",
    "STATE_BUDGET_BYTES",
    "Aligner",
    "BadDataConfig",
    "BadDataError",
    "BadDataPolicy",
    "Block",
    "Chunk",
    "Config",
    "ConfigError",
    "Example",
    "FlowtactError",
    "MisalignedError",
    "Port",
    "Source",
    "SpecError",
    "StreamSpec",
    "all_finite",
    "concat",
    "example_folder",
    "format_bytes",
    "nonfinite_counter_docs",
    "param",
    "screen_aligned",
    "screen_nonfinite",
]
