"""Nonlinear model-predictive control (:mod:`controllers.mpc.nmpc`): the real-time iteration on
a condensed QP, or converged IPOPT solves, about an optimal slew.

Builds on :mod:`controllers.design`, :mod:`controllers.slew` and :mod:`controllers.feedback`
(its estimator and terminal cost).
"""
