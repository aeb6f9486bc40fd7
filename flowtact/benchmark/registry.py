"""Where suites come from: the entry-point group ``flowtact.bench`` (flowtact's own suites and any
installed package's), plus suites registered in-process (tests, notebooks)."""

from __future__ import annotations

from dataclasses import dataclass
from importlib.metadata import entry_points

from flowtact.benchmark.suite import Suite

__all__ = ["GROUP", "Unavailable", "in_process_only", "register", "suites", "unregister"]

GROUP = "flowtact.bench"
_REGISTERED: dict[str, Suite] = {}


@dataclass(frozen=True)
class Unavailable:
    """A suite whose entry point failed to load: skipped (a missing package) or failed (a bug)."""

    name: str
    reason: str
    missing_module: bool


def register(suite: Suite) -> Suite:
    """Make ``suite`` runnable by ``flowtact bench`` in this process (it shadows an entry point)."""
    _REGISTERED[suite.name] = suite
    return suite


def in_process_only(name: str) -> bool:
    """Was suite ``name`` registered in this process (so a child process cannot find it by name)?"""
    return name in _REGISTERED


def unregister(name: str) -> None:
    _REGISTERED.pop(name, None)


def suites() -> dict[str, Suite | Unavailable]:
    """Every suite by name, sorted: entry points first loaded, then in-process registrations."""
    found: dict[str, Suite | Unavailable] = {}
    for ep in entry_points(group=GROUP):
        try:
            obj = ep.load()
        except ModuleNotFoundError as e:
            found[ep.name] = Unavailable(ep.name, f"needs the module '{e.name}' ({ep.value})", True)
            continue
        except Exception as e:  # noqa: BLE001 — a broken third-party suite must not stop the others
            found[ep.name] = Unavailable(
                ep.name, f"{ep.value} failed to load: {type(e).__name__}: {e}", False
            )
            continue
        if not isinstance(obj, Suite):
            found[ep.name] = Unavailable(ep.name, f"{ep.value} is a {type(obj).__name__}, not a Suite", False)
        elif obj.name != ep.name:
            found[ep.name] = Unavailable(ep.name, f"{ep.value} is named {obj.name!r}, not {ep.name!r}", False)
        else:
            found[ep.name] = obj
    found.update(_REGISTERED)
    return dict(sorted(found.items()))
