"""Device support for io blocks, and the blocks of generic device links (LSL); nothing here knows a domain.

=================== ==========================================================================
module              what
=================== ==========================================================================
clocksync           device clock → graph time (lower-envelope offset + drift)
ptyserver           serve a line device on a pseudo-terminal (emulators; real sleeps and clocks)
emulators           ``flowtact sim DEVICE``: runs the emulators of the ``flowtact.emulators`` group
lsl_streams         LSL streams: find one, its metadata, formats (pylsl imported lazily: the lsl extra)
lsl_clock           LSL time ↔ graph time: offset and drift to the sender, the run's anchor
lsl_inlet           the ``lsl_inlet`` block: an LSL stream into the graph
lsl_outlet          the ``lsl_outlet`` block: a graph stream published on LSL
lsl_command         ``flowtact lsl list``
lsl_force_emulator  ``flowtact sim lsl-force``: an emulated force gauge on LSL
=================== ==========================================================================
"""
