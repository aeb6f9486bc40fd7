"""Generic blocks on sample streams.

============ ================ ==========================================================
block        module           what
============ ================ ==========================================================
savgol       savgol           streaming Savitzky–Golay smoother/differentiator, units per second
weighted_sum weighted_sum     weighted sum of up to four aligned streams
delay        delay            one-tick delay: closes a feedback loop
lowpass      lowpass          first-order low-pass on the samples' own time stamps
replay       replay           plays a recording (.h5/.npz/.csv) back as a source
============ ================ ==========================================================

Helper module: ``shapes`` (the raised-cosine smooth step that scenario sources build force
profiles from).
"""
