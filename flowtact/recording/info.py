"""``flowtact info REC.h5``: what a recording holds (streams, provenance, the run's outcome) and
whether every checksum still matches, read chunk by chunk so memory stays bounded."""

from __future__ import annotations

import json
import math
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import Any

from flowtact.errors import NotARecording, RecordingCorrupted
from flowtact.inputs.safe_text import shown
from flowtact.recording.hdf5 import FORMAT, stream_header, stream_kind
from flowtact.recording.integrity import CheckedFile

__all__ = ["RecordingInfo", "StreamInfo", "format_info", "inspect_recording"]

#: Provenance keys shown (and put in --json), in this order.
PROVENANCE_KEYS = ("graph_name", "graph_seed", "flowtact_version", "command", "created_utc", "host")


@dataclass(frozen=True)
class StreamInfo:
    """One recorded stream as ``flowtact info`` shows it."""

    name: str
    kind: str  # samples, frames, events or pulses
    shape: list[int]
    dtype: str
    units: str
    rate_hz: float | None
    n_units: int | None
    labels: list[str] | None
    samples: int
    t_first: float | None
    t_last: float | None
    end_s: float | None
    bytes: int


@dataclass
class RecordingInfo:
    """What ``flowtact info`` reports: streams, provenance, the run's summary and integrity."""

    path: str
    file_bytes: int
    format_version: int | None
    streams: list[StreamInfo] = field(default_factory=list)
    damaged_streams: list[str] = field(default_factory=list)  # headers too damaged to describe
    provenance: dict[str, Any] = field(default_factory=dict)
    summary: dict[str, Any] | None = None
    integrity: str = "ok"  # "ok", "CORRUPTED" or "no checksums"
    problems: list[str] = field(default_factory=list)
    datasets_checked: int = 0

    @property
    def ok(self) -> bool:
        """False when any part of the file is damaged (a stream that cannot be described included)."""
        return not self.problems and not self.damaged_streams

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready form (``flowtact info --json``)."""
        return asdict(self)


def inspect_recording(path: str | Path) -> RecordingInfo:
    """Describe a recording and verify every checksum (every chunk of every dataset).

    A missing, non-HDF5 or truncated file raises :class:`flowtact.errors.RecordingError`
    (one line), an HDF5 file that is no recording :class:`NotARecording`; damage inside a readable
    recording is listed in ``problems``, never raised, and what can still be read is described.
    """
    p = Path(path)
    with CheckedFile(p, strict=False) as f:
        problems = f.problems()
        if "streams" not in f.file:
            raise NotARecording(f"{shown(p)}: not a flowtact recording (no /streams group)")
        info = RecordingInfo(str(p), p.stat().st_size, None, problems=[str(x) for x in problems])
        info.datasets_checked = f.datasets_checked
        bad = {x.where for x in problems}
        root, _ = f.checked_attrs(f.file)
        info.format_version = _int(root.get("format_version"))
        info.provenance = {k: _plain(root[k]) for k in PROVENANCE_KEYS if k in root}
        if isinstance(root.get("summary"), str):
            info.summary = _summary(root["summary"], info.problems)
        if "/streams" not in bad:
            for name in f.file["streams"]:
                s = _stream(f, name, bad)
                if isinstance(s, str):
                    info.damaged_streams.append(name)
                    if not any(x.where.startswith(f"/streams/{name}") for x in problems):
                        info.problems.append(f"/streams/{shown(name, limit=200)}: {s}")
                else:
                    info.streams.append(s)
        checksummed = f.checksummed
    info.integrity = "CORRUPTED" if not info.ok else ("ok" if checksummed else "no checksums")
    return info


def _int(value: Any) -> int | None:
    try:
        return int(value)
    except (TypeError, ValueError):
        return None


def _summary(text: str, problems: list[str]) -> dict[str, Any] | None:
    """The stored run summary, or None (and a problem) when it is not a JSON object."""
    try:
        value = json.loads(text)
    except (ValueError, RecursionError) as e:
        problems.append(f"/: attribute 'summary' is not JSON ({shown(e, limit=200)})")
        return None
    if not isinstance(value, dict):
        problems.append("/: attribute 'summary' is not a JSON object")
        return None
    return value


def _stream(f: CheckedFile, name: str, bad: set[str]) -> StreamInfo | str:
    """A stream's description, or why it cannot be described (its header is damaged)."""
    where = f"/streams/{name}"
    if where in bad:
        return "attributes damaged"
    try:
        h = stream_header(f, name)
        n = h.n
        t_first = t_last = None
        if n and f"{where}/t" not in bad:
            t_first, t_last = float(f.read(h.t, 0)), float(f.read(h.t, n - 1))
        end = h.attrs.get("end_s")
        end_s = float(end) if end is not None and math.isfinite(float(end)) else None
    except RecordingCorrupted as e:
        return e.what
    except KeyError as e:
        return f"cannot be described (missing {shown(e, limit=200)})"
    except (ValueError, TypeError) as e:
        return f"cannot be described ({shown(e, limit=200)})"
    spec = h.spec
    return StreamInfo(
        name=name,
        kind=str(h.attrs.get("kind") or stream_kind(spec)),
        shape=list(spec.shape),
        dtype=spec.dtype,
        units=spec.units,
        rate_hz=spec.rate_hz,
        n_units=spec.n_units,
        labels=None if spec.labels is None else list(spec.labels),
        samples=n,
        t_first=t_first,
        t_last=t_last,
        end_s=end_s,
        bytes=int(h.t.id.get_storage_size() + h.data.id.get_storage_size()),
    )


def _plain(value: Any) -> Any:
    return value.item() if hasattr(value, "item") else value


# -- text -----------------------------------------------------------------------------------


def _size(n: int) -> str:
    for unit in ("B", "kB", "MB", "GB"):
        if n < 1000 or unit == "GB":
            return f"{n:.0f} {unit}" if unit == "B" else f"{n:.1f} {unit}"
        n /= 1000  # type: ignore[assignment]
    return f"{n} B"


def _rate(s: StreamInfo) -> str:
    if s.kind in ("events", "pulses"):
        return f"events, {s.n_units} units" if s.n_units is not None else "events"
    return f"{s.rate_hz:g} Hz" if s.rate_hz else "-"


def _span(s: StreamInfo) -> str:
    if s.t_first is None:
        return "-" if s.end_s is None else f"- (end {s.end_s:.3f})"
    text = f"{s.t_first:.3f}-{s.t_last:.3f} s"
    return text + (f" (end {s.end_s:.3f})" if s.kind in ("events", "pulses") and s.end_s is not None else "")


def _table(rows: list[list[str]]) -> list[str]:
    widths = [max(len(r[i]) for r in rows) for i in range(len(rows[0]))]
    return ["  " + "  ".join(c.ljust(w) for c, w in zip(r, widths, strict=True)).rstrip() for r in rows]


#: Longest text of one field shown (names, units, provenance values); the rest is cut, its length said.
FIELD_CHARS = 200
#: Longest stored command shown.
COMMAND_CHARS = 1000


def _t(value: Any, limit: int = FIELD_CHARS) -> str:
    """A value that came from the file, as data: control characters escaped, long text cut."""
    return shown(value, limit=limit)


def _num(value: Any, spec: str) -> str:
    """A number from the file formatted with ``spec``, or the value shown as text if it is none."""
    if isinstance(value, (int, float)) and not isinstance(value, bool):
        return format(value, spec)
    return _t(value)


def _items(value: Any) -> list[tuple[Any, Any]]:
    return list(value.items()) if isinstance(value, dict) else []


def _run_lines(summary: dict[str, Any] | None) -> list[str]:
    if summary is None:
        return ["run:        no summary: the run was killed before it closed the recording"]
    parts = []
    if "duration_s" in summary:
        wall, running, startup = summary.get("wall_s"), summary.get("running_s"), summary.get("startup_s")
        took = (
            f" in {_num(running, '.2f')} s"
            if running
            else (f" in {_num(wall, '.2f')} s wall" if wall else "")
        )
        took += f" (start-up {_num(startup, '.1f')} s apart)" if running and startup is not None else ""
        parts.append(f"{_num(summary['duration_s'], '.3f')} s of graph time{took}")
    if summary.get("stopped_by"):
        parts.append(f"stopped by {_t(summary['stopped_by'])}")
    if summary.get("realtime") is False:
        parts.append("NOT real time")
    lines = [f"run:        {', '.join(parts) or 'summary stored'}"]
    lines.append(
        f"error:      {_t(summary['error'], COMMAND_CHARS)}" if summary.get("error") else "error:      none"
    )
    restarts = {
        n: p.get("restarts")
        for n, p in _items(summary.get("processes"))
        if isinstance(p, dict) and p.get("restarts")
    }
    if restarts:
        lines.append("restarts:   " + ", ".join(f"{_t(n)} {_t(k)}" for n, k in restarts.items()))
    counters = [
        f"{_t(node)}.{_t(name)} {_t(value)}"
        for node, c in _items(summary.get("counters"))
        for name, value in _items(c)
        if value
    ]
    if counters:
        lines.append("counters:   " + _t(", ".join(counters), COMMAND_CHARS))
    return lines


def format_info(info: RecordingInfo) -> str:
    """The human-readable report of ``flowtact info``: every text that came from the file is shown
    as data (:func:`flowtact.inputs.safe_text.shown`: control characters escaped, long values cut)."""
    version = f"format {info.format_version}" if info.format_version is not None else "format ?"
    lines = [f"{shown(info.path)}: {FORMAT} ({version}), {_size(info.file_bytes)}"]
    p = info.provenance
    if p:
        seed = f" (seed {_t(p['graph_seed'])})" if "graph_seed" in p else ""
        lines.append(
            f"graph:      {_t(p.get('graph_name', '?'))}{seed}, flowtact {_t(p.get('flowtact_version', '?'))}"
        )
        lines.append(f"recorded:   {_t(p.get('created_utc', '?'))} on {_t(p.get('host', '?'))}")
        if p.get("command"):
            lines.append(f"command:    {_t(p['command'], COMMAND_CHARS)}")
    lines += _run_lines(info.summary)
    if info.streams:
        rows = [["stream", "kind", "shape", "dtype", "units", "rate", "samples", "span", "size"]]
        for s in info.streams:
            shape = "(" + ", ".join(map(str, s.shape)) + ("," if len(s.shape) == 1 else "") + ")"
            rows.append(
                [
                    _t(s.name),
                    _t(s.kind),
                    _t(shape),
                    _t(s.dtype),
                    _t(s.units),
                    _t(_rate(s)),
                    str(s.samples),
                    _span(s),
                    _size(s.bytes),
                ]
            )
        lines.append(f"streams ({len(info.streams)}):")
        lines += _table(rows)
    if info.damaged_streams:
        names = ", ".join(_t(n) for n in info.damaged_streams)
        lines.append(f"damaged streams (not described): {_t(names, COMMAND_CHARS)}")
    if not info.ok:
        lines.append(f"integrity:  CORRUPTED ({len(info.problems)} damaged):")
        lines += [f"  CORRUPTED: {_t(x, COMMAND_CHARS)}" for x in info.problems]
    elif info.integrity == "ok":
        lines.append(
            f"integrity:  ok (every checksum of {info.datasets_checked} datasets and their attributes)"
        )
    else:
        lines.append("integrity:  no checksums (written before flowtact recorded them; nothing to verify)")
    return "\n".join(lines)
