"""Braille cells from the Unicode Braille block, the letters a–z, and the geometry of a line of text.

A pattern's dots are the bits of its code point − U+2800 (bit k ↔ dot k + 1), so the dot table is
never typed by hand: only the first decade (a–j) is given as dots, every other letter follows the
standard rule (k–t = a–j + dot 3; u v x y z = a–e + dots 3 and 6; w = j + dot 6, w came late to
French Braille). Dots 1, 2, 3 are the left column top to bottom, dots 4, 5, 6 the right one.

Geometry: the nominal values of DIN 32976:2007 ("Marburg Medium", the German/European Braille
standard): dot pitch 2.5 mm (within a cell, both directions), cell pitch 6.0 mm, line pitch
10.0 mm, dot base diameter 1.5 mm (1.3–1.6 allowed), dot height 0.5 mm. Bologna et al. (2013)
scaled their characters 1:1.7; :data:`PAPER_SCALE` does the same to every length, height included.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

__all__ = [
    "BRAILLE_BASE",
    "CATEGORIES",
    "LETTERS",
    "PAPER_SCALE",
    "Geometry",
    "cell_of",
    "dot_positions",
    "dots_of",
    "height_field",
    "letter_cell",
    "text_cells",
]

#: The first code point of the Unicode Braille Patterns block (the empty cell).
BRAILLE_BASE = 0x2800
#: The letters the scanner knows (a space is an empty cell).
LETTERS = "abcdefghijklmnopqrstuvwxyz"
#: The ``char`` stream's categories: 0 = between cells, 1..26 = a..z, 27 = a space (an empty cell).
CATEGORIES: tuple[str, ...] = ("gap", *LETTERS, "space")
#: Bologna et al.'s scaling of the Braille characters.
PAPER_SCALE = 1.7

#: The first decade, a–j, as dots: the one table the rule builds the alphabet from.
_DECADE = ((1,), (1, 2), (1, 4), (1, 4, 5), (1, 5), (1, 2, 4), (1, 2, 4, 5), (1, 2, 5), (2, 4), (2, 4, 5))


def cell_of(dots: frozenset[int] | tuple[int, ...]) -> int:
    """The code point of the cell with these dots (1..6 or 1..8)."""
    return BRAILLE_BASE + sum(1 << (d - 1) for d in set(dots))


def dots_of(code_point: int) -> frozenset[int]:
    """The dots of a Braille pattern: the set bits of ``code_point − U+2800``, bit k ↔ dot k + 1."""
    bits = code_point - BRAILLE_BASE
    if not 0 <= bits < 256:
        raise ValueError(f"U+{code_point:04X} is not in the Braille Patterns block (U+2800..U+28FF)")
    return frozenset(k + 1 for k in range(8) if bits >> k & 1)


def _letter_dots(letter: str) -> frozenset[int]:
    i = LETTERS.index(letter)
    if letter == "w":
        return frozenset((*_DECADE[9], 6))
    if i < 10:
        return frozenset(_DECADE[i])
    if i < 20:
        return frozenset((*_DECADE[i - 10], 3))
    j = "uvxyz".index(letter)
    return frozenset((*_DECADE[j], 3, 6))


def letter_cell(ch: str) -> int:
    """The code point of a letter's cell (a space: the empty cell U+2800)."""
    if ch == " ":
        return BRAILLE_BASE
    if len(ch) != 1 or ch not in LETTERS:
        raise ValueError(f"no Braille cell for {ch!r} (letters a-z and space only)")
    return cell_of(_letter_dots(ch))


def text_cells(text: str) -> list[int]:
    """The cells of a text of letters and spaces, in reading order."""
    return [letter_cell(ch) for ch in text]


@dataclass(frozen=True)
class Geometry:
    """Braille dimensions in mm (DIN 32976 nominal values) times ``scale``."""

    scale: float = PAPER_SCALE
    dot_pitch_mm: float = 2.5
    cell_pitch_mm: float = 6.0
    line_pitch_mm: float = 10.0
    dot_diameter_mm: float = 1.5
    dot_height_mm: float = 0.5

    @property
    def dot_pitch(self) -> float:
        return self.dot_pitch_mm * self.scale

    @property
    def cell_pitch(self) -> float:
        return self.cell_pitch_mm * self.scale

    @property
    def dot_radius(self) -> float:
        return 0.5 * self.dot_diameter_mm * self.scale

    @property
    def dot_height(self) -> float:
        return self.dot_height_mm * self.scale

    def cell_centre(self, k: int | np.ndarray) -> float | np.ndarray:
        """x of cell ``k``'s centre along the line (mm): cell k spans [k·pitch, (k+1)·pitch)."""
        return (np.asarray(k) + 0.5) * self.cell_pitch

    def cell_span(self, k: int | np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """[first, last] x (mm) where a dot of cell ``k`` can be: its two columns ± a dot radius."""
        c = np.asarray(self.cell_centre(k), np.float64)
        half = 0.5 * self.dot_pitch + self.dot_radius
        return c - half, c + half


def dot_positions(cells: list[int], geometry: Geometry) -> np.ndarray:
    """(n_dots, 3): x, y (mm) of every dot of a line of cells, and its cell index.

    Cell k's left column sits at its centre − dot_pitch/2, the right one at + dot_pitch/2; rows
    (dots 1/4, 2/5, 3/6) at y = +dot_pitch, 0, −dot_pitch: y = 0 is the middle row.
    """
    rows = []
    d = geometry.dot_pitch
    for k, cp in enumerate(cells):
        c = float(geometry.cell_centre(k))
        for dot in sorted(dots_of(cp)):
            if dot > 6:
                raise ValueError(f"cell U+{cp:04X} uses dot {dot}: only 6-dot Braille is modelled")
            col, row = divmod(dot - 1, 3)
            rows.append((c + (col - 0.5) * d, (1 - row) * d, k))
    return np.array(rows, np.float64).reshape(-1, 3)


def height_field(x: np.ndarray, y: np.ndarray, dots: np.ndarray, geometry: Geometry) -> np.ndarray:
    """Height (mm) of the embossed line at points (x, y): each dot a paraboloid dome
    ``H·(1 − ρ²/R²)`` for ρ < R (H dot height, R base radius), zero between dots (dots never overlap:
    R < dot pitch / 2)."""
    x = np.asarray(x, np.float64)
    y = np.asarray(y, np.float64)
    h = np.zeros(np.broadcast(x, y).shape)
    r2 = geometry.dot_radius**2
    for xd, yd, _ in dots:
        rho2 = (x - xd) ** 2 + (y - yd) ** 2
        h += geometry.dot_height * np.clip(1.0 - rho2 / r2, 0.0, None)
    return h
