"""Closed-loop Braille reading (Bologna et al. 2013): graphs/braille_open.yaml.

============ ================ ==========================================================
block        module           what
============ ================ ==========================================================
braille_scan scan             fingertip of 24 capacitive taxels scanning a line of Braille
============ ================ ==========================================================

``cells`` builds the cells from the Unicode Braille block and holds the (scaled) geometry;
``fingertip`` the sensor's physics; ``presets`` the neuron parameters (``preset: braille.afferent``,
``braille.cuneate`` for nlif, ``braille.cuneate`` for synapse). See docs/braille.md.
"""
