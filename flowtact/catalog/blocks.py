"""The block catalogue: block classes found through the ``flowtact.blocks`` entry-point group.

Any installed package can add blocks by declaring entry points in that group. A graph may also
name a class directly as ``package.module:Class``, but a graph is data from anyone: such a module
is imported only when the user allows it (``--allow-module MODULE`` on the command line,
``allow_modules=`` in Python), or when it belongs to a package that registers blocks (installed
code the user chose, e.g. the replay stand-ins in ``flowtact.blocks.signal.replay_ports``; never
a ``__main__``, which would run that package's command).
Nothing a file says widens the permission. See docs/security.md.

Where the framework itself needs a library block (``--replay`` needs the block that plays a file),
it asks for a **role** (:data:`ROLES`, :func:`role_block`), which an installed package fills in the
``flowtact.roles`` entry-point group; the framework never names a library block itself (the layout
test checks both).
"""

from __future__ import annotations

import importlib
import re
from collections.abc import Iterable, Iterator
from contextlib import contextmanager
from contextvars import ContextVar
from functools import cache
from importlib.metadata import entry_points

from flowtact.block import Block
from flowtact.errors import ModuleNotAllowedError, UnknownBlockError
from flowtact.params import did_you_mean

__all__ = [
    "allowing",
    "block_names",
    "check_module_name",
    "load_block",
    "module_allowed",
    "role_block",
]

GROUP = "flowtact.blocks"
ROLES_GROUP = "flowtact.roles"
ROLES: dict[str, str] = {
    "replay": "the source that plays a recorded file in place of a node (--replay): a Block class "
    "with stand_in(block: str) -> str, the reference of its stand-in on that block's own output ports",
}
"""The roles the framework asks the library to fill: name -> what the block must be and do."""
MODULE_RE = re.compile(r"[A-Za-z_][A-Za-z0-9_]*(\.[A-Za-z_][A-Za-z0-9_]*)*\Z")
"""A dotted module name: what ``--allow-module`` and the module part of ``module:Class`` must be."""

_ALLOWED: ContextVar[frozenset[str]] = ContextVar("flowtact_allowed_modules", default=frozenset())
"""The allow-list of the :func:`load_block` call in progress, so a block looked up while its module
is imported (a replay stand-in for an allowed ``module:Class``) keeps the caller's permission."""


@cache
def _entry_points() -> dict[str, object]:
    return {ep.name: ep for ep in entry_points(group=GROUP)}


@cache
def _block_packages() -> frozenset[str]:
    """The packages holding registered blocks (``flowtact.blocks.signal`` for ``...signal.savgol:SavGol``)."""
    mods = (str(ep.value).partition(":")[0] for ep in _entry_points().values())  # type: ignore[attr-defined]
    return frozenset(m.rpartition(".")[0] or m for m in mods)


def block_names() -> list[str]:
    """Every registered block name, sorted."""
    return sorted(_entry_points())


def check_module_name(text: str) -> str:
    """``text`` if it is a dotted module name (``mypkg`` or ``mypkg.blocks``); else ValueError."""
    if not MODULE_RE.match(text):
        raise ValueError(f"'{text}' is not a module name (like mypkg or mypkg.blocks)")
    return text


def module_allowed(module: str, allow: Iterable[str]) -> bool:
    """Whether ``module`` is one of ``allow`` or inside one of them (``mypkg`` allows ``mypkg.sub``)."""
    return any(module == a or module.startswith(a + ".") for a in allow)


@contextmanager
def allowing(modules: Iterable[str]) -> Iterator[None]:
    """Within this block, :func:`load_block` also imports ``module:Class`` blocks of ``modules``
    (module names or package prefixes, as ``--allow-module``): how a graph's loading gets the
    user's permission without passing it through every helper."""
    token = _ALLOWED.set(_ALLOWED.get() | frozenset(modules))
    try:
        yield
    finally:
        _ALLOWED.reset(token)


def role_block(role: str) -> type[Block]:
    """The block class an installed package registers for ``role`` (one of :data:`ROLES`) in the
    ``flowtact.roles`` entry-point group; UnknownBlockError if none does, or it is not a Block."""
    found = [ep for ep in entry_points(group=ROLES_GROUP) if ep.name == role]
    if role not in ROLES or not found:
        raise UnknownBlockError(
            f"no installed package provides the '{role}' block ({ROLES_GROUP} entry points: "
            f"{ROLES.get(role, 'not a role of flowtact')})"
        )
    cls = found[0].load()
    if not (isinstance(cls, type) and issubclass(cls, Block)):
        raise UnknownBlockError(f"the '{role}' role ({found[0].value}) is not a flowtact Block")
    return cls


def load_block(name: str, allow_modules: Iterable[str] = ()) -> type[Block]:
    """The block class registered as ``name``, or imported from ``module:Class`` when
    ``allow_modules`` (module names or package prefixes) allows that module; a module that is not
    allowed is never imported (:class:`ModuleNotAllowedError`)."""
    if name == "shard_slice":
        from flowtact.graphfile.shards import ShardSlice

        return ShardSlice
    if name.startswith("shard_merge["):
        from flowtact.graphfile.shards import MERGE_RE, merge_class

        m = MERGE_RE.match(name)
        if m is None:
            raise UnknownBlockError(f"block '{name}' is not shard_merge[<block>]")
        return merge_class(load_block(m.group(1), allow_modules))
    if ":" in name:
        module, _, attr = name.partition(":")
        allow = _ALLOWED.get() | frozenset(allow_modules)
        if not MODULE_RE.match(module) or not attr:
            raise UnknownBlockError(f"block '{name}' is neither a registered block nor module:Class")
        installed = "__main__" not in module.split(".") and module_allowed(module, _block_packages())
        if not (installed or module_allowed(module, allow)):
            raise ModuleNotAllowedError(
                f"block '{name}' names a Python module; flowtact imports only registered blocks "
                f"unless you allow it: --allow-module {module}"
            )
        try:
            with allowing(allow):
                cls = getattr(importlib.import_module(module), attr)
        except (ImportError, AttributeError) as e:
            raise UnknownBlockError(f"cannot import block '{name}': {e}") from None
    else:
        ep = _entry_points().get(name)
        if ep is None:
            raise UnknownBlockError(f"unknown block '{name}'{did_you_mean(name, _entry_points())}")
        cls = ep.load()  # type: ignore[attr-defined]
    if not (isinstance(cls, type) and issubclass(cls, Block)):
        raise UnknownBlockError(f"'{name}' is not a flowtact Block")
    return cls
