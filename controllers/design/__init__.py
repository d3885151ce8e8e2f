"""What every design shares: the plant as a law reads it, and the checks a design passes.

======================  ========================================================================
module                  contents
======================  ========================================================================
``plant_state``         the plant's state layout, the design state and the hub state a law reads
``controllable``        controllability of a design model, LQR on its controllable part
``stability``           the closed loop's stability on the full plant (``check_loop``)
``actuator_limits``     what an actuator allows a design: torque bounds, horizons' constraints
``hold_grid``           RK4 substeps of a held input on a design model's fastest mode
``native_dynamics``     a design model's dynamics compiled once, for the optimisers
======================  ========================================================================

Imports nothing from the other subpackages of :mod:`controllers`.
"""
