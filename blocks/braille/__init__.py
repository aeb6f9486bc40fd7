"""Closed-loop Braille reading (Bologna et al. 2013): graphs/braille_open.yaml.

==================== ================ ======================================================
block                module           what
==================== ================ ======================================================
braille_cell_windows cell_windows     the decoder's character windows from the finger's position
braille_scan         scan             fingertip of 24 capacitive taxels scanning a line of Braille
speed_controller     speed_controller scanning speed from the decoder's confidence; lateral corrector
==================== ================ ======================================================

``reading`` runs a Braille graph in process and cuts its spikes into character windows;
``train_braille`` is ``flowtact train-braille`` (the decoder's model, ``models/braille_first.npz``,
for graphs/braille.yaml, the closed loop).

``cells`` builds the cells from the Unicode Braille block and holds the (scaled) geometry;
``fingertip`` the sensor's physics; ``presets`` the neuron parameters (``preset: braille.afferent``,
``braille.cuneate`` for nlif, ``braille.cuneate`` for synapse). See docs/braille.md.
"""
