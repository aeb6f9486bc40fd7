"""Text that came from a file or a library, made safe to print: control characters shown escaped."""

from __future__ import annotations

import re
from typing import Any

__all__ = ["BIDI_CONTROLS", "shown"]

BIDI_CONTROLS = "\u061c\u200e\u200f\u202a\u202b\u202c\u202d\u202e\u2066\u2067\u2068\u2069"
"""Characters that change the display order of the text around them (Trojan Source)."""

_UNSAFE = re.compile("[\x00-\x1f\x7f-\x9f\u2028\u2029\ud800-\udfff" + re.escape(BIDI_CONTROLS) + "]")
_NAMED = {"\n": "\\n", "\r": "\\r", "\t": "\\t"}


def _escape(m: re.Match[str]) -> str:
    ch = m.group()
    if ch in _NAMED:
        return _NAMED[ch]
    code = ord(ch)
    return f"\\x{code:02x}" if code < 0x80 else f"\\u{code:04x}"


def shown(text: Any, limit: int | None = None) -> str:
    """``text`` safe to print on one line: C0/C1 controls, line separators and bidi overrides
    escaped (``\\x1b``, ``\\u202e``); cut to ``limit`` characters when given."""
    if isinstance(text, (bytes, bytearray, memoryview)):
        s = bytes(text).decode("utf-8", "surrogateescape")
    else:
        s = text if isinstance(text, str) else str(text)
    tail = ""
    if limit is not None and len(s) > limit:
        tail = f"… ({len(s):,} characters)"
        s = s[: max(0, limit)]
    return _UNSAFE.sub(_escape, s) + tail
