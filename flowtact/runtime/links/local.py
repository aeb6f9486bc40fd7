"""The local link: nodes in one process, joined by the consumer's inbox list.

``put`` is the inbox's own ``append`` (a bound builtin: the cheapest call the hot loop can make);
through a delay port it appends to a list of its own, moved into the inbox when the tick ends.
"""

from __future__ import annotations

from flowtact.chunk import Chunk, StreamSpec
from flowtact.runtime.links import Link, register_link

__all__ = ["LocalLink"]


@register_link("local")
class LocalLink(Link):
    """An in-process link: a list append now, or (delayed) at the end of the tick."""

    def __init__(self, spec: StreamSpec, inbox: list[Chunk], *, delayed: bool = False) -> None:
        super().__init__(spec, inbox, delayed=delayed)
        self.holds = delayed
        self.held: list[Chunk] = []
        self.put = self.held.append if delayed else inbox.append

    def tick_done(self) -> None:
        if self.held:
            self.inbox.extend(self.held)
            self.held.clear()

    def end(self) -> None:
        self.put = self.inbox.append

    def drop(self) -> None:
        self.held.clear()
