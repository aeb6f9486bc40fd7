"""The pipelines that bench/transport.py compares flowtact with: raw pyzmq and the peer frameworks.

``raw`` runs in the bench's own environment; ``ezmsg_pipe`` and ``timeflux_pipe`` are scripts run
by the Python of a throw-away venv holding that framework; ``measure`` (stdlib and numpy only)
is shared by all of them, so every stack is measured the same way.
"""
