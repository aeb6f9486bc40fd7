"""The standard block library, installed as ``flowtact.blocks``: generic families and science domains.

Generic families (no paper's numbers, no domain imports):

=========== ===============================================================================
signal      sample streams: savgol, weighted_sum, delay, lowpass, replay
spiking     spikes: nlif (noisy LIF populations), rate, pulses (stimulation)
devices     device support beside the io blocks: clock sync, pty serving, ``flowtact sim``
=========== ===============================================================================

Domains (one per paper; a domain imports the framework and generic families, never another domain):

=========== ===============================================================================
touch       Rager et al.: AuNP strain-gauge sensor, calibration, the SA1/FA1 presets
teleop      White 2023: TacTip images to force, exoskeleton kinematics, force feedback, serial
=========== ===============================================================================

A Braille domain (Bologna et al. 2013) gets a room of its own, ``braille``, beside these.
Blocks are found through the ``flowtact.blocks`` entry points (pyproject.toml); each package's
docstring lists its blocks. docs/architecture.md has the import rules.
"""
