"""reStructuredText docstrings as plain text (flowtact.help.rst_text)."""

import pytest

from flowtact.help.rst_text import inline_text, latex_text, rst_to_text


@pytest.mark.parametrize(
    ("rst", "text"),
    [
        (":class:`~flowtact.chunk.Chunk`", "Chunk"),
        (":class:`flowtact.chunk.Chunk`", "flowtact.chunk.Chunk"),
        (":func:`the runner <flowtact.testing.run_offline>`", "the runner"),
        (":py:meth:`Block.step`", "Block.step"),
        ("``x * y``", "x * y"),
        ("``a`` and ``b``", "a and b"),
        ("*emphasis* and **strong**", "emphasis and strong"),
        ("a * b and 2*x", "a * b and 2*x"),
        ("`Brian2 <https://briansimulator.org>`_", "Brian2 (https://briansimulator.org)"),
        ("`interpreted`", "interpreted"),
        ("``:class:`kept``` inside a literal", ":class:`kept` inside a literal"),
        (r":math:`\tau \cdot x_{i}^{2}`", "τ · x_i^2"),
        (r"\*args", "*args"),
        ("|w| ≈ 1e-3", "|w| ≈ 1e-3"),
    ],
)
def test_inline_markup_becomes_its_text(rst, text):
    assert inline_text(rst) == text


@pytest.mark.parametrize(
    ("tex", "text"),
    [
        (r"\frac{1}{\tau}", "1/τ"),
        (r"\frac{a + b}{2}", "(a + b)/2"),
        (r"\sigma \sqrt{\tau/2}", "σ √(τ/2)"),
        (r"v \le 1 \quad \mathrm{and} \quad t \ge 0", "v ≤ 1 and t ≥ 0"),
        (r"\left( x \right)", "( x )"),
        (r"10\,\mathrm{ms}", "10 ms"),
    ],
)
def test_math_reads_as_symbols(tex, text):
    assert latex_text(tex) == text


def test_directives_become_labels_and_literal_blocks_stay():
    doc = (
        "Intro::\n\n    x = ``raw`` *kept*\n\n"
        ".. note:: Read :func:`run_offline` first.\n   Second line.\n\n"
        ".. warning::\n\n   Careful.\n\n"
        ".. math::\n\n   v = \\frac{1}{\\tau}\n\n"
        ".. code-block:: python\n   :linenos:\n\n   print('hi')\n\n"
        ".. _target:\n\n"
        "Intro2 ::\n\n    y\n\nEnd."
    )
    text = rst_to_text(doc, 80)
    assert text.splitlines() == [
        "Intro:",
        "",
        "    x = ``raw`` *kept*",
        "",
        "Note: Read run_offline first.",
        "   Second line.",
        "",
        "Warning:",
        "",
        "   Careful.",
        "",
        "   v = 1/τ",
        "",
        "   print('hi')",
        "",
        "Intro2",
        "",
        "    y",
        "",
        "End.",
    ]


def test_paragraphs_and_items_wrap_with_hanging_indents_and_doctests_do_not():
    doc = (
        "A paragraph " + "word " * 30 + "\nends.\n\n"
        "* a bullet " + "item " * 20 + "\n  continued\n* second\n\n"
        "name : type\n    description " + "more " * 20 + "\n\n"
        ">>> x = 1  # " + "long comment " * 10 + "\n"
        "Section\n-------\n"
    )
    lines = rst_to_text(doc, 40).splitlines()
    prose = [ln for ln in lines if not ln.startswith(">>>")]
    assert max(map(len, prose)) <= 40
    assert any(len(ln) > 40 for ln in lines if ln.startswith(">>>"))  # a doctest is never re-wrapped
    bullet = lines.index(next(ln for ln in lines if ln.startswith("* a bullet")))
    assert lines[bullet + 1].startswith("  item") and not lines[bullet + 1].startswith("   ")
    assert "  continued" in " ".join(lines)
    desc = lines.index("name : type")
    assert lines[desc + 1].startswith("    description") and lines[desc + 2].startswith("    more")
    assert lines[-2:] == ["Section", "-------"]
