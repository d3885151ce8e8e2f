"""Slew design: reference profiles, input shaping and trajectory optimisation.

===================  ===========================================================================
module               contents
===================  ===========================================================================
``reference``        smooth rest-to-rest slew profiles (poly7, cycloidal)
``shaping``          rigid bang-bang torque and ZV / ZVD input shaping
``trajopt``          CasADi/IPOPT slew optimisation (:func:`~controllers.slew.trajopt.solve_slew`)
``slew_nlp``         the optimisation's transcription: intervals, holds, the NLP
``slew_checks``      a slew problem refused before it is solved, with the reason
``eigenaxis``        a three-axis rest-to-rest slew about a fixed axis, with its feedforward
===================  ===========================================================================

Builds on :mod:`controllers.design`; the feedback laws build on it.
"""
