"""Text that came from a file, shown as data: control characters escaped, long text cut.

A recording, model or table may hold any text: stream names, units, a stored command, a library's
error message quoting the file. Printed raw, an escape sequence in it can retitle the terminal,
clear the screen or forge a line ("integrity: ok"); a bidirectional override can reorder what the
reader sees. :func:`shown` makes such text inert before it reaches a terminal or a figure:

- C0 and C1 control characters, DEL, line and paragraph separators and lone surrogates (bytes that
  were not UTF-8) become ``\\x1b``, ``\\n``, ``\\u009b``, ``\\u2028``, ``\\udcff`` (so a field stays
  one line);
- bidirectional controls (U+061C, U+200E, U+200F, U+202A-U+202E, U+2066-U+2069) become ``\\u202e``;
- with ``limit``, text longer than ``limit`` characters is cut and says how long it was.

Everything else (accents, CJK, emoji, backslashes) is left as it is: ``shown`` is for display,
not a reversible encoding. JSON output needs none of this: ``json.dumps`` escapes control
characters itself (and, with the default ``ensure_ascii=True``, every non-ASCII character).

Example:
    >>> shown("sensor\\x1b]0;pwned\\x07.r")
    'sensor\\\\x1b]0;pwned\\\\x07.r'
    >>> shown("x" * 10, limit=4)
    'xxxx… (10 characters)'
"""

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
    """``text`` (any object; bytes decoded as UTF-8) safe to print on one line: control, separator
    and bidirectional-override characters escaped; cut to ``limit`` characters when given."""
    if isinstance(text, (bytes, bytearray, memoryview)):
        s = bytes(text).decode("utf-8", "surrogateescape")
    else:
        s = text if isinstance(text, str) else str(text)
    tail = ""
    if limit is not None and len(s) > limit:
        tail = f"… ({len(s):,} characters)"
        s = s[: max(0, limit)]
    return _UNSAFE.sub(_escape, s) + tail
