"""A three-axis law and its compiled C on the same inputs: the inputs a run's law read at
each of its samples, fed to both."""

import numpy as np


def _start(law, names):
    return law.start(names) if getattr(law, "state_feedback", False) else law.start()


def largest_command_difference(law, c_law, run) -> float:
    """Largest ``|u_python - u_c|`` (N m) over the samples of ``run`` (a
    :class:`~flexctl.sim.spatial_run.SpatialResult` of a loop), each law started on the run's
    plant and fed, sample after sample, what the law read there (the attitude and the rate, and
    for a state-feedback law the whole state): an estimator inside a law runs along in both.
    """
    names = run.equations.layout.state_names
    python, compiled = _start(law, names), _start(c_law, names)
    c = run.layout.n_coordinates
    worst = 0.0
    for k, t in enumerate(run.t):
        args = (t, run.states[0:4, k], run.states[c:c + 3, k])
        if getattr(law, "state_feedback", False):
            args += (run.states[:, k],)
        worst = max(worst, float(np.max(np.abs(python(*args) - compiled(*args)))))
    return worst


def flown_as_python(law, c_law, fly) -> tuple:
    """``(commands, states, run)``: the largest command difference (N m) of the two laws on
    the inputs of the Python law's run, the largest state difference between the runs each
    law flies, and the Python run; ``fly(law)`` flies a law and returns its
    :class:`~flexctl.sim.spatial_run.SpatialResult`."""
    run = fly(law)
    flown = fly(c_law)
    return (largest_command_difference(law, c_law, run),
            float(np.max(np.abs(flown.states - run.states))), run)
