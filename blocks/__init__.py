"""The standard block library: the tactile science lives here, one module per family.

Installed as ``flowtact.blocks``; blocks are found through the ``flowtact.blocks`` entry points.
"""
