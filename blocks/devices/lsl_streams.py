"""LSL streams as flowtact sees them: find one by name/type/source id, read its metadata, map formats.

pylsl is imported only inside the functions (the ``lsl`` extra): importing this module costs nothing.
A stream's metadata (channel count, format, nominal rate, channel labels and units in the
``<desc><channels><channel>`` convention of the XDF meta-data spec) becomes the spec of the port
that carries it. Resolving waits on the network (here: loopback, see docs/lsl.md), so a graph
asks once per process and query (:func:`find_stream` caches what it found).
"""

from __future__ import annotations

import dataclasses
import json
import subprocess
import sys
import threading
from dataclasses import dataclass
from typing import Any

from flowtact.running.python_child import python_command

__all__ = [
    "FORMATS",
    "LslNotFound",
    "StreamMeta",
    "find_stream",
    "forget",
    "list_streams",
    "meta_of",
    "open_inlet",
    "query_text",
    "watch",
]

#: LSL channel format name -> the dtype of the flowtact port carrying it ("" : not a numeric stream).
FORMATS: dict[str, str] = {
    "float32": "float32",
    "double64": "float64",
    "int8": "int8",
    "int16": "int16",
    "int32": "int32",
    "int64": "int64",
    "string": "",
}
#: pylsl's channel-format codes (cf_float32 = 1 ... cf_int64 = 7) -> names.
_CODES = {1: "float32", 2: "double64", 3: "string", 4: "int32", 5: "int16", 6: "int8", 7: "int64"}


class LslNotFound(LookupError):
    """No stream matched within the timeout (the message says what was asked and what is there)."""


@dataclass(frozen=True)
class StreamMeta:
    """What flowtact reads from an LSL stream's info (the full info, with its ``desc``)."""

    name: str
    type: str
    source_id: str
    channel_count: int
    channel_format: str
    nominal_srate: float
    hostname: str
    uid: str
    labels: tuple[str, ...] = ()
    units: tuple[str, ...] = ()

    @property
    def dtype(self) -> str:
        return FORMATS.get(self.channel_format, "")

    def line(self) -> str:
        """One line for ``flowtact lsl list``."""
        rate = "irregular" if self.nominal_srate == 0 else f"{self.nominal_srate:g} Hz"
        unit = ",".join(sorted(set(self.units))) or "-"
        return (
            f"{self.name}\t{self.type or '-'}\t{self.source_id or '-'}\t{self.channel_count}\t"
            f"{self.channel_format}\t{rate}\t{unit}\t{self.hostname}"
        )


def query_text(name: str | None, type_: str | None, source_id: str | None) -> str:
    """The query in words and as an LSL predicate: ``name='force' and type='Force'``."""
    parts = [f"{k}='{v}'" for k, v in (("name", name), ("type", type_), ("source_id", source_id)) if v]
    return " and ".join(parts)


def meta_of(info: Any) -> StreamMeta:
    """The metadata of a pylsl ``StreamInfo`` (channel labels/units when its desc has them)."""
    labels: list[str] = []
    units: list[str] = []
    ch = info.desc().child("channels").child("channel")
    while not ch.empty():
        labels.append(ch.child_value("label"))
        units.append(ch.child_value("unit"))
        ch = ch.next_sibling("channel")
    n = int(info.channel_count())
    return StreamMeta(
        name=info.name(),
        type=info.type(),
        source_id=info.source_id(),
        channel_count=n,
        channel_format=_CODES.get(int(info.channel_format()), str(info.channel_format())),
        nominal_srate=float(info.nominal_srate()),
        hostname=info.hostname(),
        uid=info.uid(),
        labels=tuple(labels) if len(labels) == n and any(labels) else (),
        units=tuple(units) if len(units) == n and any(units) else (),
    )


_found: dict[tuple[str, float], StreamMeta] = {}
_lock = threading.Lock()


def find_stream(name: str | None, type_: str | None, source_id: str | None, timeout_s: float) -> StreamMeta:
    """The metadata of the first stream matching every given field; :class:`LslNotFound` after
    ``timeout_s``. Asked in a child process: liblsl starts I/O threads that a worker forked from
    this process (the supervisor compiles the graph, then forks) would inherit broken. Cached per
    query for this process: a graph compiled, checked and bound resolves once."""
    pred = query_text(name, type_, source_id)
    key = (pred, timeout_s)
    with _lock:
        if key not in _found:
            argv = python_command("-m", __name__, pred, repr(timeout_s))
            try:
                done = subprocess.run(
                    argv, capture_output=True, text=True, timeout=timeout_s + 60, check=False
                )
            except subprocess.TimeoutExpired:
                raise LslNotFound(f"looking for the LSL stream with {pred} hung (killed)") from None
            lines = done.stdout.strip().splitlines()
            try:
                answer = json.loads(lines[-1]) if lines else {}
            except ValueError:
                answer = {}
            if "error" in answer or "name" not in answer:
                why = answer.get("error") or (done.stderr.strip().splitlines() or ["no answer"])[-1]
                raise LslNotFound(why)
            _found[key] = StreamMeta(**{k: tuple(v) if isinstance(v, list) else v for k, v in answer.items()})
        return _found[key]


def forget(name: str | None, type_: str | None, source_id: str | None, timeout_s: float) -> None:
    """Drop a cached resolution (a stream that went away: the next ask resolves again)."""
    with _lock:
        _found.pop((query_text(name, type_, source_id), timeout_s), None)


def open_inlet(pred: str, timeout_s: float, buffer_s: int) -> tuple[Any, StreamMeta]:
    """A connected pylsl inlet on the first stream matching ``pred``, and its metadata;
    :class:`LslNotFound` when there is none within ``timeout_s``. With liblsl's recovery on: an
    inlet without it raises at the next pull once the stream is lost, *before* handing out the
    samples it had already received (they would be lost); the caller watches for the stream's
    disappearance itself (:func:`watch`)."""
    import pylsl

    hits = pylsl.resolve_bypred(pred, 1, timeout_s)
    if not hits:
        raise LslNotFound(f"no LSL stream with {pred} within {timeout_s:g} s")
    inlet = pylsl.StreamInlet(hits[0], max_buflen=buffer_s, recover=True)
    inlet.open_stream(timeout_s)
    return inlet, meta_of(inlet.info(timeout_s))


def watch(uid: str, forget_after_s: float) -> Any:
    """A pylsl ContinuousResolver for the one stream ``uid`` names: its ``results()`` (a
    non-blocking read of what liblsl's background discovery last saw) is empty once the stream has
    not answered for ``forget_after_s``."""
    import pylsl

    return pylsl.ContinuousResolver(pred=f"uid='{uid}'", forget_after=forget_after_s)


def _answer(pred: str, timeout_s: float) -> dict[str, Any]:
    """What the child prints: the stream's metadata, or the error with the streams seen."""
    import pylsl

    hits = pylsl.resolve_bypred(pred, 1, timeout_s)
    if not hits:
        there = [meta_of(i) for i in pylsl.resolve_streams(0.5)]
        seen = ", ".join(sorted(f"{m.name} ({m.type or 'no type'})" for m in there)) or "none"
        return {
            "error": f"no LSL stream with {pred} within {timeout_s:g} s (streams seen: {seen}; "
            "`flowtact lsl list` shows them)"
        }
    inlet = pylsl.StreamInlet(hits[0])
    try:
        return dataclasses.asdict(meta_of(inlet.info(timeout_s)))
    except RuntimeError as e:  # it vanished between answering the query and sending its header
        return {"error": f"the LSL stream with {pred} did not send its metadata: {e}"}
    finally:
        inlet.close_stream()


def list_streams(timeout_s: float = 1.0) -> list[StreamMeta]:
    """Every stream visible within ``timeout_s``, with full metadata, by name."""
    import pylsl

    metas = []
    for info in pylsl.resolve_streams(timeout_s):
        inlet = pylsl.StreamInlet(info)
        try:
            metas.append(meta_of(inlet.info(timeout_s)))
        except RuntimeError:  # gone meanwhile: list it with what the discovery answer said
            metas.append(meta_of(info))
        finally:
            inlet.close_stream()
    return sorted(metas, key=lambda m: (m.name, m.source_id, m.uid))


if __name__ == "__main__":  # the child of find_stream: python -m ... PREDICATE TIMEOUT
    print(json.dumps(_answer(sys.argv[1], float(sys.argv[2]))), flush=True)
