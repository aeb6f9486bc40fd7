"""Slip and touch encoding for neuroprostheses (Rager et al.): graphs/touch.yaml, graphs/slip.yaml.

============ ================ ==========================================================
block        module           what
============ ================ ==========================================================
aunp_sensor  aunp_sensor      synthetic AuNP strain-gauge bump: touch and slip trials, 1 kHz
gauge_force  calibration      ΔR/R of four gauges (+ reference) → [Fx, Fy, Fz] (eq. 1–2)
shear_angle  calibration      shear angle Θ (eq. 3)
============ ================ ==========================================================

``presets`` holds the paper's numbers as presets of generic blocks (``preset: touch.SA1`` for
weighted_sum and nlif, ``touch.rager`` for savgol); ``aunp`` the sensor's physical constants.
"""
