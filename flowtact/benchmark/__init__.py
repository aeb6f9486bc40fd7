"""The benchmark harness behind ``flowtact bench``: suites register under the entry-point group
``flowtact.bench`` and measure through a :class:`Context`; the runner writes results/*.json, PNG
plots and REPORT.md. It knows nothing of what the suites measure (they live in bench/)."""

from flowtact.benchmark.registry import GROUP, register, suites, unregister
from flowtact.benchmark.suite import Context, Figure, Suite, Tradeoff
from flowtact.benchmark.timing import spread, time_call
from flowtact.errors import SuiteSkipped

__all__ = [
    "GROUP",
    "Context",
    "Figure",
    "Suite",
    "SuiteSkipped",
    "Tradeoff",
    "register",
    "spread",
    "suites",
    "time_call",
    "unregister",
]
