"""Controller designs whose Riccati equation cannot be solved say so, by name, in one line.

A model with an absurd beam (1.8e6 m: slew-90's 1.8 m given in micrometres) has clamped
frequencies far below micro-radians per second beside a hub inertia of some 1e18 kg m^2; the
Riccati solvers fail on it.
Every design reports that as an :class:`~flexctl.model.errors.InputValueError` naming the law,
the design function, the model's frequencies and ``J0``, its weights and the solver's reason
(:func:`controllers.design.controllable.design_failure`), and ``flexctl run`` prints it in one line.
"""

import numpy as np
import pytest
import scipy.linalg

import flexctl
from controllers import LQRWeights, NoiseLevels
from controllers.design.controllable import design_failure
from flexctl.app.cli import EXIT_BAD_INPUT, main
from flexctl.model.errors import InputTypeError, InputValueError

#: A beam length in micrometres read as metres.
ABSURD_LENGTH = 1.8e6
WEIGHTS = LQRWeights(hub_angle=0.05, torque=6.0)
#: What every design failure message says about the model and the solver.
MODEL_FACTS = (r"failed on a model with 2 modes, first clamped frequency \S+ rad/s, fastest "
               r"mode \S+ rad/s, J0 \S+ kg m\^2")


@pytest.fixture(scope="module")
def absurd_model():
    """slew-90's system with a 1.8e6 m beam, as its exact plant with 2 modes."""
    scene = flexctl.load_scene("slew-90", {"beam.length": ABSURD_LENGTH})
    return flexctl.build_model(scene.system, n_modes=2, variant="exact")


def _design_lqr(model):
    from controllers import design_lqr

    return design_lqr(model, WEIGHTS)


def _design_sampled_lqr(model):
    from controllers import design_lqr

    return design_lqr(model, WEIGHTS, sample_time=0.01)


def _design_lqg(model):
    from controllers import design_lqg

    return design_lqg(model, WEIGHTS, NoiseLevels(angle=1e-3, root_moment=0.1, torque=1.0))


def _design_scheduled(model):
    from controllers import design_scheduled_lqr

    return design_scheduled_lqr(model, WEIGHTS, [0.0, 1.0])


def _design_wheel_lqr(model):
    from controllers.feedback.actuated import design_wheel_lqr
    from flexctl.model.actuators import ReactionWheel

    wheel = ReactionWheel(inertia=0.02, torque_limit=0.2, speed_limit=600.0, time_constant=0.05)
    return design_wheel_lqr(model, wheel, WEIGHTS)


def _nmpc_terminal_weight(model):
    from controllers import NMPC

    return NMPC(model=model, target=0.3, torque_limit=6.0, sample_time=0.05,
                horizon=10).prepare()


@pytest.mark.parametrize("design, named, solving", [
    pytest.param(_design_lqr, r"lqr design \(design_lqr\)", "the LQR Riccati equation",
                 id="lqr"),
    pytest.param(_design_sampled_lqr, r"lqr design \(design_lqr\)", "the LQR Riccati equation",
                 id="lqr-sampled"),
    pytest.param(_design_lqg, r"lqg design \(design_lqg\)", "the LQR Riccati equation",
                 id="lqg"),
    pytest.param(_design_scheduled, r"scheduled lqr design \(design_scheduled_lqr\)",
                 "the LQR Riccati equation", id="scheduled"),
    # the wheel's LQR starts from the structure's own LQR design, which fails first
    pytest.param(_design_wheel_lqr, r"lqr design \(design_lqr\)", "the LQR Riccati equation",
                 id="wheel-lqr"),
    pytest.param(_nmpc_terminal_weight, r"nmpc design \(NMPC terminal weight\)",
                 "the discrete LQR Riccati equation", id="nmpc-terminal-weight"),
])
def test_a_riccati_failure_names_the_design_the_model_and_the_reason(absurd_model, design,
                                                                      named, solving):
    with pytest.raises(InputValueError, match=rf"^{named} {MODEL_FACTS} \(spin rate \S+ rad/s"
                       rf", .*\): {solving} has no stabilising solution \(.+\)$") as caught:
        design(absurd_model)
    assert "\n" not in str(caught.value)
    # the solver's own exception is kept as the cause, for whoever debugs the solver
    assert caught.value.__cause__ is not None


def test_the_estimator_design_names_the_kalman_filter(monkeypatch):
    """A Kalman filter whose Riccati solver fails (a failure put in its place here)."""
    from controllers import lqg

    def unsolvable(*args, **kwargs):
        raise np.linalg.LinAlgError("Failed to find a finite solution.")

    monkeypatch.setattr(lqg, "lqe_on_part", unsolvable)
    model = flexctl.build_model(flexctl.load_scene("hub-beam-mass").system, n_modes=2)
    with pytest.raises(InputValueError, match=rf"^lqg design \(estimator_gain\) {MODEL_FACTS} "
                       r"\(spin rate 0 rad/s, noise=NoiseLevels\(.*\)\): the Kalman filter "
                       r"Riccati equation has no stabilising solution \(Failed to find a "
                       r"finite solution\)$"):
        lqg.estimator_gain(model, NoiseLevels(angle=1e-3, root_moment=0.1, torque=1.0))


def test_zero_tracking_weights_leave_the_tracker_riccati_unsolvable():
    """No weight on any state: the rigid-body mode is not detectable in the cost, and the
    tracker's LQR has no stabilising solution on a sound model."""
    from controllers.feedback.tracking import TrajectoryTracker
    from controllers.slew.trajopt import SlewProblem, solve_slew

    model = flexctl.build_model(flexctl.load_scene("hub-beam-mass").system, n_modes=2)
    solution = solve_slew(model, SlewProblem(angle=0.5, duration=2.0, torque_bound=6.0))
    with pytest.raises(InputValueError,
                       match=r"^trajectory tracker lqr design \(TrajectoryTracker\) "
                             rf"{MODEL_FACTS} .*state_weights=\[0\. 0\. .*: the LQR Riccati "
                             r"equation has no stabilising solution"):
        TrajectoryTracker(solution=solution, state_weights=np.zeros(model.n_states))
    with pytest.raises(InputTypeError, match=r"^TrajectoryTracker takes keyword arguments "
                                             r"only: TrajectoryTracker\(solution=\.\.\."):
        TrajectoryTracker(solution)


def test_design_failure_converts_solver_failures_only():
    model = flexctl.build_model(flexctl.load_scene("hub-beam-mass").system, n_modes=1)
    with pytest.raises(InputValueError, match=r"^pd design \(f\) .*torque_weight=2\): the LQR "
                                              r"Riccati equation has no stabilising solution "
                                              r"\(Singular matrix\)$"):
        with design_failure("pd", "f", model, torque_weight=2.0):
            np.linalg.inv(np.zeros((2, 2)))
    # a ValueError raised inside SciPy's Riccati solver, not one of numpy's LinAlgErrors
    with pytest.raises(InputValueError, match=r"solving the LQR Riccati equation failed "
                                              r"\(ValueError: "):
        with design_failure("pd", "f", model):
            scipy.linalg.solve_continuous_are(np.eye(2), np.ones((3, 1)), np.eye(2),
                                              np.eye(1))
    # the project's own input errors and our own bugs pass through untouched
    own = InputValueError("lqr_weights.torque must be positive; got -1")
    with pytest.raises(InputValueError) as caught:
        with design_failure("pd", "f", model):
            raise own
    assert caught.value is own
    with pytest.raises(ValueError, match="^a bug$"):
        with design_failure("pd", "f", model):
            raise ValueError("a bug")
    with pytest.raises(ZeroDivisionError):
        with design_failure("pd", "f", model):
            1 / 0


def test_flexctl_run_reports_a_failed_design_in_one_line(tmp_path, monkeypatch, capsys):
    """``--set beam.length=1.8e+06`` (micrometres by mistake): exit 2 and one line that names
    the design and the reason."""
    monkeypatch.chdir(tmp_path)
    code = main(["run", "slew-90", "--set", f"beam.length={ABSURD_LENGTH:g}",
                 "--set", "controller.kind=scheduled", "--out", str(tmp_path / "out")])
    captured = capsys.readouterr()
    assert code == EXIT_BAD_INPUT
    lines = captured.err.splitlines()
    assert len(lines) == 1, captured.err
    assert lines[0].startswith("flexctl: error: controller: scheduled lqr design "
                               "(design_scheduled_lqr) failed on a model with")
    assert "has no stabilising solution (" in lines[0]
    assert "Traceback" not in captured.err
    assert not (tmp_path / "out").exists()


def test_noise_levels_whose_squares_overflow_are_refused_by_name():
    from controllers.feedback.lqg import NoiseLevels
    from flexctl.app.cli import main

    for value in (1e300, 1e-200, 0.0, -1.0, float("nan"), float("inf")):
        with pytest.raises(InputValueError, match="noise.torque"):
            NoiseLevels(angle=1e-3, root_moment=0.1, torque=value)
    assert main(["run", "slew-90", "--set", "controller.kind=lqg", "--set",
                 "controller.process_torque=1e300", "--out", "/dev/null/x"]) == 2
