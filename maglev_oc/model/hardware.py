"""Hardware constants of the Quanser 2-DOF rig that every layer agrees on (002 Sec. 4, 000 Sec. II)."""

RIG_SAMPLE_TIME = 2e-4
"""Control period [s]: the Q8 board runs the loop at 5 kHz."""
ENCODER_RESOLUTION = 10e-6
"""Linear optical encoders, both axes [m]."""
CONTINUOUS_CURRENT_LIMIT = 7.0
"""LCAM continuous current [A]."""
PEAK_CURRENT_LIMIT = 9.0
"""LCAM peak current [A]."""
