"""Analysis of a designed loop: transfer functions, margins, poles against spin, robustness.

==================  ============================================================================
module              contents
==================  ============================================================================
``channels``        the plant's channels from the hub torque
``loops``           loop transfer functions, stability margins, poles against spin
``dispersion``      dispersed stiffness, point masses, hub inertia, whole or per appendage
``robustness``      Monte Carlo of a design flown on dispersed plants, and its spread
``spatial_loops``   the three-axis quaternion loop on the flexible spacecraft, its disk margins
``requirements``    loop requirements as data, verified nominally and over the uncertainty
``filter_design``   structural filters placed until the requirements hold
==================  ============================================================================

Builds on the laws (:mod:`controllers.feedback`).
"""

from .loops import (SENSORS, LoopMargins, PlantChannels, PolesVsSpin, loop_margins,
                    loop_transfer, plant_channels, poles_vs_spin)

from .spatial_loops import DiskMargins, quaternion_disk_margins, quaternion_loop

__all__ = ["SENSORS", "PlantChannels", "plant_channels", "loop_transfer", "LoopMargins",
           "loop_margins", "PolesVsSpin", "poles_vs_spin", "DiskMargins",
           "quaternion_disk_margins", "quaternion_loop"]
