"""The exoskeleton's serial line protocol (docs/serial-protocol.md), host and device side alike.

:func:`frame` / :func:`unframe` (``$…*XX`` lines with an NMEA-style XOR checksum), the messages
:class:`DataPacket`, :class:`Command`, :class:`Hello`, :class:`Query`, :class:`DeviceError`, and
:func:`parse_line`. No I/O and no device model: what a firmware or a host needs to talk.
"""

from __future__ import annotations

from dataclasses import dataclass

import flowtact.api as ft

__all__ = [
    "ADC_MAX",
    "DEVICE_MAX_DEV_US",
    "PROTOCOL_VERSION",
    "Command",
    "DataPacket",
    "DeviceError",
    "Hello",
    "ProtocolError",
    "Query",
    "checksum",
    "frame",
    "parse_line",
    "unframe",
]

PROTOCOL_VERSION = 1
DEVICE_NAME = "flowtact-exo"
N_FINGERS = 3
#: The device's own clamp on commanded deviations (the host clamps tighter).
DEVICE_MAX_DEV_US = 800
ADC_MAX = 1023
TICK_WRAP = 1 << 32
SEQ_WRAP = 1 << 16


# -- line protocol ------------------------------------------------------------------------------


class ProtocolError(ft.FlowtactError, ValueError):
    """A line that is not a valid protocol message (bad framing, checksum, field count or range)."""


def checksum(body: bytes) -> int:
    """XOR of all bytes of ``body`` (what lies between ``$`` and ``*``)."""
    c = 0
    for b in body:
        c ^= b
    return c


def frame(body: str) -> bytes:
    """``$body*XX\\n`` with XX the checksum in upper-case hex."""
    raw = body.encode("ascii")
    return b"$" + raw + b"*%02X\n" % checksum(raw)


def unframe(line: bytes, *, require_checksum: bool = True) -> str:
    """The body of one line (without its ``\\n``); raises :class:`ProtocolError`.

    Anything before the last ``$`` is ignored (line noise at connect); a ``\\r`` before the end is
    tolerated. Without ``require_checksum`` a line with no ``*XX`` is accepted, but a wrong
    checksum is always an error.
    """
    line = line.rstrip(b"\r\n")
    start = line.rfind(b"$")
    if start < 0:
        raise ProtocolError("no '$' start")
    line = line[start + 1 :]
    star = line.rfind(b"*")
    if star < 0:
        if require_checksum:
            raise ProtocolError("no checksum")
        body = line
    else:
        body, tail = line[:star], line[star + 1 :]
        try:
            want = int(tail, 16)
        except ValueError:
            raise ProtocolError("checksum is not hex") from None
        if len(tail) != 2 or checksum(body) != want:
            raise ProtocolError("checksum mismatch")
    try:
        return body.decode("ascii")
    except UnicodeDecodeError:
        raise ProtocolError("non-ASCII bytes") from None


@dataclass(frozen=True)
class DataPacket:
    """One device sample: tick (µs, uint32), 9 angles (mrad), 3 FSR readings, status, last ack."""

    tick_us: int
    phi_mrad: tuple[int, ...]  # φ1, φ2, φ3 of thumb, then index, then middle
    fsr_adc: tuple[int, int, int]
    status: int  # bits 0-2: servo engaged (thumb, index, middle); bit 3: watchdog tripped
    ack: int  # sequence number of the last command applied (0 before any)
    host_ns: int | None = None  # optional 'h=' field: true sampling time on the host clock (emulators)

    def format(self) -> bytes:
        fields = ["D", str(self.tick_us), *map(str, self.phi_mrad), *map(str, self.fsr_adc)]
        fields += [str(self.status), str(self.ack)]
        if self.host_ns is not None:
            fields.append(f"h={self.host_ns}")
        return frame(",".join(fields))


@dataclass(frozen=True)
class Command:
    """Host → device: per finger engage (0/1) and deviation (µs); ``seq`` is echoed as the ack."""

    seq: int
    engage: tuple[int, int, int]
    dev_us: tuple[int, int, int]

    def format(self) -> bytes:
        parts = ["C", str(self.seq)]
        for e, d in zip(self.engage, self.dev_us, strict=True):
            parts += [str(int(e)), str(int(d))]
        return frame(",".join(parts))


@dataclass(frozen=True)
class Hello:
    """Device → host at connect and on a ``$V`` query: name, protocol version, packet rate."""

    name: str
    version: int
    rate_hz: float

    def format(self) -> bytes:
        return frame(f"H,{self.name},{self.version},{self.rate_hz:g}")


@dataclass(frozen=True)
class Query:
    """Host → device ``$V``: please send your hello line."""

    def format(self) -> bytes:
        return frame("V")


@dataclass(frozen=True)
class DeviceError:
    """Device → host ``$E,<code>``: the device rejected something (``badsum``, ``badcmd``)."""

    code: str

    def format(self) -> bytes:
        return frame(f"E,{self.code}")


Message = DataPacket | Command | Hello | Query | DeviceError


def _int(s: str, lo: int, hi: int, what: str) -> int:
    try:
        v = int(s)
    except ValueError:
        raise ProtocolError(f"{what} is not an integer: {s!r}") from None
    if not lo <= v <= hi:
        raise ProtocolError(f"{what} out of range [{lo}, {hi}]: {v}")
    return v


def parse_line(line: bytes, *, require_checksum: bool = True) -> Message:
    """Parse one line (with or without its newline) into a message; raises :class:`ProtocolError`."""
    f = unframe(line, require_checksum=require_checksum).split(",")
    kind = f[0]
    if kind == "D":
        extras = [x for x in f[1:] if "=" in x]
        fixed = [x for x in f[1:] if "=" not in x]
        if len(fixed) != 15:
            raise ProtocolError(f"data line has {len(fixed)} fields, expected 15")
        tick = _int(fixed[0], 0, TICK_WRAP - 1, "tick")
        phi = tuple(_int(x, -10_000, 10_000, "angle") for x in fixed[1:10])
        fsr = tuple(_int(x, 0, ADC_MAX, "fsr") for x in fixed[10:13])
        status = _int(fixed[13], 0, 255, "status")
        ack = _int(fixed[14], 0, SEQ_WRAP - 1, "ack")
        host_ns = None
        for x in extras:
            key, _, val = x.partition("=")
            if key == "h":
                host_ns = _int(val, 0, 1 << 63, "h")
        return DataPacket(tick, phi, fsr, status, ack, host_ns)  # type: ignore[arg-type]
    if kind == "C":
        if len(f) != 8:
            raise ProtocolError(f"command has {len(f) - 1} fields, expected 7")
        seq = _int(f[1], 0, SEQ_WRAP - 1, "seq")
        eng = tuple(_int(x, 0, 1, "engage") for x in f[2::2])
        dev = tuple(_int(x, -10_000, 10_000, "deviation") for x in f[3::2])
        return Command(seq, eng, dev)  # type: ignore[arg-type]
    if kind == "H":
        if len(f) != 4:
            raise ProtocolError("hello needs name, version, rate")
        try:
            rate = float(f[3])
        except ValueError:
            raise ProtocolError(f"hello rate is not a number: {f[3]!r}") from None
        return Hello(f[1], _int(f[2], 0, 1 << 16, "version"), rate)
    if kind == "V" and len(f) == 1:
        return Query()
    if kind == "E" and len(f) == 2:
        return DeviceError(f[1])
    raise ProtocolError(f"unknown message {kind!r}")
