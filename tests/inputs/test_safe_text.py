"""Text from files is shown as data: every control, separator and bidi-override character escaped."""

import pytest

from flowtact.inputs.safe_text import BIDI_CONTROLS, shown


@pytest.mark.parametrize(
    "raw,want",
    [
        ("\x1b]0;pwned\x07", "\\x1b]0;pwned\\x07"),  # OSC title change
        ("\x1b[2J\x1b[H", "\\x1b[2J\\x1b[H"),  # clear screen, cursor home
        ("a\nintegrity:  ok\r", "a\\nintegrity:  ok\\r"),  # a forged line
        ("\x00\x7f\x9b", "\\x00\\x7f\\u009b"),  # NUL, DEL, C1 CSI
        ("x\u2028y\u2029", "x\\u2028y\\u2029"),
        (b"\xff\x1b", "\\udcff\\x1b"),  # bytes that are not UTF-8
        ("ünï 😀 N·m \\", "ünï 😀 N·m \\"),  # ordinary text is left alone
    ],
)
def test_controls_are_escaped_and_text_is_kept(raw, want):
    assert shown(raw) == want


def test_every_c0_c1_and_bidi_character_is_escaped():
    for code in [*range(0x20), *range(0x7F, 0xA0), *map(ord, BIDI_CONTROLS)]:
        out = shown(chr(code))
        assert out.startswith("\\") and out.isprintable() and out.isascii(), hex(code)


def test_limit_cuts_and_says_how_long():
    assert shown("x" * 10, limit=4) == "xxxx… (10 characters)"
    assert shown("x" * 4, limit=4) == "xxxx"
    assert shown(12.5) == "12.5"
