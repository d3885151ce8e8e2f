"""Analysis of a designed loop: transfer functions, margins, poles against spin, robustness.

==================  ============================================================================
module              contents
==================  ============================================================================
``loops``           loop transfer functions, stability margins, poles against spin
``robustness``      Monte Carlo dispersion of stiffness, point masses, hub inertia
==================  ============================================================================

Builds on the laws (:mod:`controllers.feedback`).
"""

from .loops import (SENSORS, LoopMargins, PlantChannels, PolesVsSpin, loop_margins,
                    loop_transfer, plant_channels, poles_vs_spin)

__all__ = ["SENSORS", "PlantChannels", "plant_channels", "loop_transfer", "LoopMargins",
           "loop_margins", "PolesVsSpin", "poles_vs_spin"]
