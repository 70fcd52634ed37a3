"""Hardware constants of the Quanser 2-DOF rig that every layer agrees on (002 Sec. 4, 000 Sec. II)."""

__all__ = [
    "CONTINUOUS_CURRENT_LIMIT",
    "ENCODER_RESOLUTION",
    "MICROSTEPPER_STOPPER_GAP",
    "PEAK_CURRENT_LIMIT",
    "RIG_SAMPLE_TIME",
    "STOPPER_GAP",
    "STOPPER_POSITION",
]

RIG_SAMPLE_TIME = 2e-4
"""Control period [s]: the Q8 board runs the loop at 5 kHz."""
ENCODER_RESOLUTION = 10e-6
"""Linear optical encoders, both axes [m]."""
CONTINUOUS_CURRENT_LIMIT = 7.0
"""LCAM continuous current [A]."""
PEAK_CURRENT_LIMIT = 9.0
"""LCAM peak current [A]."""
STOPPER_GAP = (8e-3, 30e-3)
"""Gap between the vertical stoppers [m] (002 Fig. 5: about 10 mm of travel, the stoppers a little
outside the working range)."""
STOPPER_POSITION = (-60e-3, 60e-3)
"""Horizontal position between the stoppers [m] (about +-50 mm of travel, 002 Sec. 4)."""
MICROSTEPPER_STOPPER_GAP = (8e-3, 35e-3)
"""Gap between the microstepper's vertical stoppers [m] (assumed: 002 Sec. 8 gives the operating
range 20-30 mm, so the upper stopper sits outside it, not on its edge as the 2-DOF's 30 mm does)."""
