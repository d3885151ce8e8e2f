"""Every run says why it ended, as a StopReason whose status is the result's."""

import dataclasses
import warnings

import numpy as np

import flexctl
from flexctl.sim import StopReason
from flexctl.sim.digital import ZeroOrderHold


def test_reached_end():
    model = flexctl.build_model(flexctl.load_scene("hub-beam-mass").system, n_modes=2)
    result = flexctl.simulate(model, 1.0, torque=flexctl.SineTorque(peak_torque=1.0,
                                                                     duration=0.5))
    assert result.stop_reason is StopReason.REACHED_END and result.status == "ok"


def test_zero_order_spinning_past_its_first_frequency_passes_the_length():
    scene = flexctl.load_scene("kane-spinup")
    model = flexctl.build_model(scene.system, n_modes=2, variant="zero_order")
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        for method in ("auto", "rk4"):
            result = flexctl.simulate(model, 30.0, hub_motion=scene.maneuver, method=method)
            assert result.stop_reason is StopReason.TIP_PAST_LENGTH, method
            assert result.status == "diverged"
            assert "passed the beam length" in result.message


def test_sampled_runaway_passes_the_length():
    model = flexctl.build_model(flexctl.load_scene("hub-beam-mass").system, n_modes=2)
    law = ZeroOrderHold(lambda t, x: 1e4, sample_time=0.01)
    result = flexctl.simulate(model, 5.0, controller=law)
    assert result.stop_reason is StopReason.TIP_PAST_LENGTH
    assert np.all(np.isfinite(result.states))


def test_every_reason_maps_to_a_status():
    statuses = {reason: reason.status for reason in StopReason}
    assert statuses[StopReason.REACHED_END] == "ok"
    assert statuses[StopReason.SINGULAR_MASS] == "singular"
    assert {s for r, s in statuses.items()
            if r not in (StopReason.REACHED_END, StopReason.SINGULAR_MASS)} == {"diverged"}


def test_compiled_fallback_locates_the_stop_where_the_python_path_does():
    """Where a compiled segment fails, SciPy locates the stop on the compiled right-hand
    side: the same stop, to the integrator's tolerance, as the Python model gives."""
    scene = flexctl.load_scene("hub-beam-mass")
    model = scene.build_model()
    push = flexctl.SineTorque(peak_torque=1e5, duration=2.0)
    stops = {method: flexctl.simulate(model, 20.0, torque=push, method=method)
             for method in ("cvodes", "DOP853")}
    for result in stops.values():
        assert result.stop_reason is StopReason.TIP_PAST_LENGTH
    assert abs(stops["cvodes"].t[-1] - stops["DOP853"].t[-1]) < 1e-6 * stops["DOP853"].t[-1]
    assert np.allclose(stops["cvodes"].states[:, -1], stops["DOP853"].states[:, -1],
                       rtol=1e-4, atol=1e-6)


def _heavy_tip_on_a_massless_hub():
    """hub-beam-mass with a massless hub and a 6e5 kg tip mass: exact, 2 modes."""
    base = flexctl.load_scene("hub-beam-mass").system
    system = dataclasses.replace(base, hub=dataclasses.replace(base.hub, inertia=0.0),
                                 masses=(flexctl.PointMass(mass=6e5, position=1.8),))
    return flexctl.build_model(system, n_modes=2, variant="exact")


def test_a_state_too_stiff_to_follow_ends_with_its_stiffness_named(monkeypatch):
    """Where CVODES cannot pass a state (made to fail at t = 0 here) and
    the explicit fallback runs out of its evaluations on a stiff beam (1e5 times stiffer than
    hub-beam-mass's; the budget cut to 2000 evaluations), the run ends as an integrator
    failure naming the stiffness it met."""
    from flexctl.sim import compiled, strategies

    def cannot_pass(self, y0):
        raise RuntimeError("CVODES: the step size fell below its minimum at t = 0")

    monkeypatch.setattr(compiled.SegmentIntegrator, "__call__", cannot_pass)
    monkeypatch.setattr(strategies, "FALLBACK_EVALUATIONS", 2000)
    base = flexctl.load_scene("hub-beam-mass").system
    beam = dataclasses.replace(base.beam, youngs_modulus=1e5 * base.beam.youngs_modulus)
    model = flexctl.build_model(dataclasses.replace(base, beam=beam), n_modes=2,
                                variant="exact")
    result = flexctl.simulate(model, 1.0, torque=flexctl.SineTorque(peak_torque=1.0,
                                                                     duration=0.5),
                              method="cvodes")
    assert result.stop_reason is StopReason.INTEGRATOR_FAILED
    assert "2e+03 evaluations of DOP853" in result.message
    assert "stiff (fastest rate" in result.message
    assert np.all(np.isfinite(result.states))
    # the rate named is the stiff beam's: its frequencies are sqrt(1e5) = 316 times
    # hub-beam-mass's
    rate = float(result.message.split("fastest rate ")[1].split(" ")[0])
    assert rate > 100.0 * flexctl.build_model(base, n_modes=2).natural_frequencies()[-1]


def test_heavy_tip_on_a_massless_hub_keeps_its_energy_balance():
    """The same structure followed to the end by CVODES: the exact model's energy equals the
    work of the hub torque (the structure has neither friction nor damping)."""
    model = _heavy_tip_on_a_massless_hub()
    result = flexctl.simulate(model, 1.0, torque=flexctl.SineTorque(peak_torque=1.0,
                                                                     duration=0.5))
    assert result.stop_reason is StopReason.REACHED_END
    energy = np.array([float(model.geometry.energy(x)) for x in result.states.T])
    power = result.torque * result.theta_dot
    work = np.concatenate(([0.0], np.cumsum(0.5 * (power[1:] + power[:-1])
                                            * np.diff(result.t))))
    lost = energy - work
    assert np.max(np.abs(lost)) <= 1e-3 * np.max(energy)
