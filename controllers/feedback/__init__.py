"""Feedback laws: PD, LQR, LQG, gain scheduling, tracking, observers and actuator-aware laws.

======================  ========================================================================
module                  contents
======================  ========================================================================
``reference_feedback``  the base of the laws that follow a reference slew
``pd``                  collocated PD on hub angle and rate
``lqr``                 LQR with Bryson-style physical weights, state truncation
``lqg``                 Kalman filter on hub angle and root moment plus LQR
``lqg_sampled``         LQG with its estimator discretised at a sample time
``scheduling``          LQR gains scheduled on the spin rate
``tracking``            feedforward plus LQR feedback about an optimal slew
``observer``            a sampled discrete Kalman filter of noisy sensor readings
``mekf``                a multiplicative extended Kalman filter of attitude and gyro bias
``quaternion``          three-axis quaternion feedback (proportional, rate, integral)
``spatial_lqr``         three-axis LQR and LQG on the linear flexible spacecraft
``actuated``            laws through an actuator: wheel-lag LQR, DC-motor voltage, limits
``iosys``               the laws as python-control I/O systems for ``control.interconnect``
``observed_loop``       an observed law's loop as it flies: sampled, late, through its filter
``structural_filters``  notch, roll-off and lead-lag filters on a sampled law's command
======================  ========================================================================

Builds on :mod:`controllers.design` and :mod:`controllers.slew`.
"""

from .reference_feedback import (ReferenceFeedback, ReferenceSaturationWarning,
                                 warn_if_reference_saturates)

__all__ = ["ReferenceFeedback", "ReferenceSaturationWarning", "warn_if_reference_saturates"]
