"""Device support for io blocks: nothing here is a block, and nothing here knows a domain.

============ ==========================================================================
module       what
============ ==========================================================================
clocksync    device clock → graph time (lower-envelope offset + drift)
ptyserver    serve a line device on a pseudo-terminal (emulators; real sleeps and clocks)
emulators    ``flowtact sim DEVICE``: runs the emulators of the ``flowtact.emulators`` group
============ ==========================================================================
"""
