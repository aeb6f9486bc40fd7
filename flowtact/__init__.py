"""flowtact: YAML graphs of reusable streaming blocks for tactile sensing and haptics."""

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
    "SafeYamlError",
    "SecurityError",
    "Source",
    "SpecError",
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
    "screen_nonfinite",
    "sweep",
]
