"""Braille cells from the Unicode block, the alphabet rule, and the height field of a line."""

import unicodedata

import numpy as np
import pytest

from flowtact.blocks.braille.cells import (
    BRAILLE_BASE,
    LETTERS,
    Geometry,
    cell_of,
    dot_positions,
    dots_of,
    height_field,
    letter_cell,
    text_cells,
)

#: Six-dot letters, as any Braille primer prints them: read here only to name the expected dots.
PRIMER = "a1 b12 c14 d145 e15 f124 g1245 h125 i24 j245 k13 l123 m134 n1345 o135 p1234 q12345 r1235 s234 t2345 u136 v1236 w2456 x1346 y13456 z1356"


def _unicode_dots(cp: int) -> str:
    """The dots Unicode names a pattern by: 'BRAILLE PATTERN DOTS-1245' → '1245'."""
    name = unicodedata.name(chr(cp))
    assert name.startswith("BRAILLE PATTERN")
    return "" if name == "BRAILLE PATTERN BLANK" else name.removeprefix("BRAILLE PATTERN DOTS-")


def test_dots_are_the_bits_of_the_code_point_over_the_whole_block():
    for cp in range(BRAILLE_BASE, BRAILLE_BASE + 256):
        dots = dots_of(cp)
        assert "".join(str(d) for d in sorted(dots)) == _unicode_dots(cp)
        assert cell_of(dots) == cp


@pytest.mark.parametrize("letter", list(LETTERS))
def test_each_letter_maps_to_the_cell_unicode_names_with_its_dots(letter):
    expected = dict((e[0], e[1:]) for e in PRIMER.split())[letter]
    assert _unicode_dots(letter_cell(letter)) == expected


def test_the_alphabet_is_26_distinct_cells_and_a_space_is_blank():
    cells = text_cells(LETTERS)
    assert len(set(cells)) == 26 and BRAILLE_BASE not in cells
    assert letter_cell(" ") == BRAILLE_BASE
    with pytest.raises(ValueError, match="no Braille cell for '1'"):
        letter_cell("1")
    with pytest.raises(ValueError, match="not in the Braille Patterns block"):
        dots_of(0x41)


def test_geometry_is_din_32976_scaled_1_to_1_7():
    g = Geometry()
    assert g.dot_pitch == pytest.approx(4.25) and g.cell_pitch == pytest.approx(10.2)
    assert g.dot_radius == pytest.approx(1.275) and g.dot_height == pytest.approx(0.85)


def test_dot_positions_put_dots_1_to_6_in_two_columns_of_three_rows():
    g = Geometry()
    d = dot_positions([cell_of((1, 2, 3, 4, 5, 6))], g)
    c, p = g.cell_pitch / 2, g.dot_pitch
    expected = [
        (c - p / 2, p),
        (c - p / 2, 0),
        (c - p / 2, -p),
        (c + p / 2, p),
        (c + p / 2, 0),
        (c + p / 2, -p),
    ]
    np.testing.assert_allclose(d[:, :2], expected)
    assert dot_positions(text_cells("ab"), g)[:, 2].tolist() == [0, 1, 1]  # a: 1 dot; b: 2, in cell 1


def test_height_field_has_domes_exactly_where_the_cells_dots_are():
    g = Geometry()
    dots = dot_positions(text_cells("n"), g)  # n = dots 1, 3, 4, 5
    p, c1 = g.dot_pitch, g.cell_pitch / 2
    left, right = c1 - p / 2, c1 + p / 2
    at = {(left, p): 1, (left, 0.0): 0, (left, -p): 1, (right, p): 1, (right, 0.0): 1, (right, -p): 0}
    for (x, y), present in at.items():
        assert height_field(np.array(x), np.array(y), dots, g) == pytest.approx(present * g.dot_height)
    # the dome's profile: H(1 − ρ²/R²), zero at and beyond the rim
    rho = np.array([0.0, 0.5, 1.0, 1.2, 1.275, 1.5])
    h = height_field(left + rho, np.full_like(rho, p), dots, g)
    np.testing.assert_allclose(h, g.dot_height * np.clip(1 - rho**2 / g.dot_radius**2, 0, None), atol=1e-15)
    between = height_field(np.array(c1), np.array(p / 2), dots, g)
    assert between == 0.0  # paper between the dots
