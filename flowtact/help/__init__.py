"""Docs and help rendering: reStructuredText docstrings as terminal text, and `flowtact blocks NAME`."""
