"""flowtact: YAML graphs of reusable streaming blocks for tactile sensing and haptics."""

from typing import TYPE_CHECKING, Any

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
from flowtact.errors import (
    BadDataError,
    BlockSpecsFailed,
    ConfigError,
    ConformanceError,
    FileRefused,
    FlowtactError,
    GraphFileError,
    MisalignedError,
    ModuleNotAllowedError,
    NodeError,
    NodeFailure,
    NotARecording,
    ProcessFailure,
    RecordingCorrupted,
    RecordingError,
    RecordingRefused,
    SafeYamlError,
    SecurityError,
    SpecError,
    SuiteSkipped,
    SweepSpecError,
    UnknownBlockError,
    UsageError,
    WireError,
    WorkerDied,
    WorkerFailed,
    WorkerStop,
)
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
    "BadDataError",
    "BadDataPolicy",
    "Block",
    "BlockSpecsFailed",
    "Chunk",
    "Config",
    "ConfigError",
    "ConformanceError",
    "Example",
    "FileRefused",
    "FlowtactError",
    "GraphBuilder",
    "GraphFileError",
    "MisalignedError",
    "ModuleNotAllowedError",
    "NodeError",
    "NodeFailure",
    "NotARecording",
    "Port",
    "ProcessFailure",
    "RecordingCorrupted",
    "RecordingError",
    "RecordingRefused",
    "RunResult",
    "SafeYamlError",
    "SecurityError",
    "Source",
    "SpecError",
    "Stream",
    "StreamSpec",
    "SuiteSkipped",
    "SweepSpecError",
    "UnknownBlockError",
    "UsageError",
    "WireError",
    "WorkerDied",
    "WorkerFailed",
    "WorkerStop",
    "__version__",
    "concat",
    "nonfinite_counter_docs",
    "param",
    "read_streams",
    "run",
    "screen_nonfinite",
    "sweep",
]
