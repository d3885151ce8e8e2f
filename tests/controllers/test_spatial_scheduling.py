"""Gain scheduling over the spin in three axes (issue 44, item 4): the gains are the designs at
the design spins and interpolated between, the schedule holds a loop that the design at rest
loses at a spin 2.5 times the arrays' first bending frequency, and a sparse schedule says
where it fails."""

import shutil
import warnings

import numpy as np
import pytest
from spatial_craft import WING

from controllers.design.plant_state import spatial_design_plant
from controllers.design.stability import LoopStabilityWarning
from controllers.feedback.lqr import LQRWeights
from controllers.feedback.spatial_lqr import spatial_lq_gain
from controllers.feedback.spatial_scheduling import (GROWTH_TOLERANCE, SteadySpin,
                                                     design_scheduled_spatial_lqr)
from flexctl.model.errors import InputTypeError, InputValueError
from flexctl.model.spatial_structure import SpatialAppendage, SpatialHub, SpatialStructure
from flexctl.sim.maneuvers import SpinUp
from flexctl.sim.quaternions import error_angles
from flexctl.sim.spatial_loop import simulate_spatial_loop

WEIGHTS = LQRWeights(hub_angle=0.01, hub_rate=0.02, tip_deflection=0.005, torque=2.0)
SPIN = 20.0            # rad/s; the arrays' first bending mode at rest is near 7.8 rad/s


def _craft():
    """Two arrays along +-y, soft along x (in the plane of a spin about z), on a hub whose
    principal axes are the frame's: z is a principal axis perpendicular to both arrays, the
    largest; x the intermediate one."""
    wing = dict(WING, normal=(1, 0, 0))
    return SpatialStructure(hub=SpatialHub(inertia=np.diag([1.3, 1.2, 1.4]), radius=0.3),
                            appendages=(SpatialAppendage(**wing),
                                        SpatialAppendage(**dict(wing, name="wing_b",
                                                                direction=(0, -1, 0)))))


CRAFT = _craft()


def _design(rates, profile=1.0, axis=(0, 0, 1), n_modes=1, **options):
    return design_scheduled_spatial_lqr(CRAFT, WEIGHTS, axis, rates, profile, n_modes=n_modes,
                                        sample_time=0.05, variant="first_order", **options)


def test_the_gains_are_the_designs_at_the_design_spins_and_interpolated_between():
    law = _design([0.0, 4.0, 8.0])
    for k, spin in enumerate((0.0, 4.0, 8.0)):
        plant, names = spatial_design_plant("test", CRAFT, 1, "first_order",
                                            angular_velocity=(0.0, 0.0, spin))
        gain, _, _ = spatial_lq_gain("test", CRAFT, plant, WEIGHTS, sample_time=0.05)
        np.testing.assert_allclose(law.gain_at(spin), gain, rtol=1e-9, atol=1e-12)
        assert names == law.state_names
    np.testing.assert_allclose(law.gain_at(5.0), 0.75 * law.gains[1] + 0.25 * law.gains[2])
    np.testing.assert_array_equal(law.gain_at(-3.0), law.gains[0])
    np.testing.assert_array_equal(law.gain_at(30.0), law.gains[2])
    # the spin changes the plant: the gains differ across the schedule
    assert np.max(np.abs(law.gains[2] - law.gains[0])) > 0.05 * np.max(np.abs(law.gains[0]))
    assert [spin for spin, _ in law.between] == [2.0, 6.0]


def test_the_design_at_rest_loses_the_spinning_loop_that_the_schedule_holds():
    """At 20 rad/s about z, the gain designed at rest leaves a pole of the linear loop growing
    (measured: 8.1e-2 1/s); the schedule over 0, 5, ..., 20 rad/s holds every design spin and
    every spin halfway between (no pole above the tolerance: the parts the torque does not
    move stay on the axis). Flown on the nonlinear model through a spin-up to 20 rad/s in 10 s
    with a small initial nutation, the design at rest's error relative to the spinning
    reference grows after the spin-up (measured 2.2e-4 rad at 20 s, 1.2e-2 at 50 s) and the
    scheduled law's falls (1.4e-4 and 6.0e-5)."""
    profile = SpinUp(spin_rate=SPIN, ramp_time=10.0)
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        scheduled = _design(np.linspace(0.0, SPIN, 5), profile)
    rest = _design([0.0], profile)
    assert max(growth for _, growth in scheduled.between) < GROWTH_TOLERANCE
    for spin in (5.0, 10.0, 20.0):
        assert np.max(scheduled.loop_poles(spin).real) < GROWTH_TOLERANCE
    assert np.max(rest.loop_poles(SPIN).real) > 0.05
    errors, tips = {}, {}
    for name, law in (("scheduled", scheduled), ("rest", rest)):
        run = simulate_spatial_loop(CRAFT, 50.0, law, sample_time=0.05, n_modes=1,
                                    variant="first_order", rtol=1e-8,
                                    angular_velocity=(0.02, -0.01, 0.0)).result
        assert run.ok, run.message
        error = np.array([np.linalg.norm(error_angles(law.reference_at(t)[0], q))
                          for t, q in zip(run.t, run.quaternion.T)])
        at = [int(np.argmin(np.abs(run.t - t))) for t in (20.0, 50.0)]
        errors[name] = error[at]
        tips[name] = np.abs(run.tips["wing_a"][:, at[1]]).max()
        c = run.layout.n_coordinates
        assert run.states[c + 2, -1] == pytest.approx(SPIN, rel=1e-3)
    print(errors, tips)
    assert errors["scheduled"][1] < errors["scheduled"][0] < 1e-3
    assert errors["rest"][1] > 10 * errors["rest"][0]
    assert tips["rest"] > 30 * tips["scheduled"]


def test_the_broken_loop_at_a_spin_closes_the_loop_the_schedule_holds_there():
    """``lq_loop(law, plant, spin=...)``: the held loop the gain interpolated at the spin
    closes around the plant linearised about it, the poles of :meth:`loop_poles`; the spin
    is required."""
    from controllers.analysis.spatial_loops import loop_disk_margins, lq_loop

    law = _design([0.0, 4.0, 8.0])
    for spin in (4.0, 6.0):
        margins = loop_disk_margins(lq_loop(law, law.plant_at(spin), spin=spin))
        assert margins.spectral_abscissa == pytest.approx(
            np.max(law.loop_poles(spin).real), abs=1e-9)
        assert margins.closed_loop_stable and np.all(margins.disk_margin > 0.3)
    with pytest.raises(InputValueError, match=r"lq_loop\.spin is required"):
        lq_loop(law, law.plant_at(4.0))


def test_a_schedule_too_sparse_where_the_plant_changes_fast_says_where():
    """About x (the intermediate principal axis: the rigid spin is unstable on its own), with
    two modes per field, the gain interpolated halfway between 10 and 15 rad/s loses the loop
    the two designs hold (measured: a pole growing at 0.15 1/s)."""
    with pytest.warns(LoopStabilityWarning, match=r"at 12.5 rad/s a pole grows"):
        law = _design([0.0, 5.0, 10.0, 15.0], axis=(1, 0, 0), n_modes=2)
    growth = dict(law.between)
    assert growth[12.5] > 1e-2 and growth[2.5] < GROWTH_TOLERANCE
    assert all(np.max(p.real) < 0 for p in law.poles)


def test_a_steady_spin_is_followed_from_a_spinning_start():
    """A number as the profile: a steady spin, the reference starting at the craft's
    attitude; the craft already spinning at it stays on it."""
    law = _design([1.5, 3.0], 2.0)
    assert isinstance(law.profile, SteadySpin) and law.profile.spin_rate == 2.0
    run = simulate_spatial_loop(CRAFT, 5.0, law, sample_time=0.05, n_modes=1, rtol=1e-10,
                                variant="first_order", angular_velocity=(0.0, 0.0, 2.0)).result
    error = max(np.linalg.norm(error_angles(law.reference_at(t)[0], q))
                for t, q in zip(run.t, run.quaternion.T))
    print(f"error {error:.1e} rad, torque {np.abs(run.torque).max():.1e} N m")
    assert error < 1e-8 and np.abs(run.torque).max() < 1e-7


def test_bad_schedules_are_refused_by_name():
    with pytest.raises(InputValueError, match=r"spin 2 rad/s about \[0.707107, 0.0, 0.707107\]"
                                              r".*no steady turn"):
        _design([0.0, 2.0], axis=(1, 0, 1))              # not a principal axis
    with pytest.raises(InputValueError, match="strictly increasing"):
        _design([2.0, 1.0])
    with pytest.raises(InputValueError, match="spin_rates"):
        _design([])
    with pytest.raises(InputTypeError, match=r"profile must have a callable angle"):
        _design([0.0], profile=object())
    with pytest.raises(InputTypeError, match=r"profile must have a callable angle"):
        _design([0.0], profile=True)
    with pytest.raises(InputValueError, match=r"spin_rates must be a sequence .* shape \(2, 2\)"):
        _design([[0.0, 1.0], [2.0, 3.0]])
    with pytest.raises(InputValueError, match="n_modes"):
        _design([0.0], n_modes=0)
    with pytest.raises(InputValueError, match="gain_at.spin must be finite"):
        _design([0.0, 1.0]).gain_at(np.nan)
    with pytest.raises(InputValueError, match="spin_rate"):
        SteadySpin(spin_rate=np.inf)
    with pytest.raises(InputValueError, match="spin_axis"):
        _design([0.0], axis=(0, 0, 0))
    with pytest.raises(InputValueError, match="no state 'wing_a.ql1'"):
        _design([0.0]).start(("qw", "qx", "qy", "qz", "wing_a.qn1"))


@pytest.mark.skipif(shutil.which("cc") is None and shutil.which("gcc") is None,
                    reason="no C compiler")
def test_the_scheduled_law_as_c_commands_and_flies_as_python(tmp_path):
    """Through the spin-up to 10 rad/s (its angle, rate and acceleration, and the gains
    interpolated in the measured spin, written as C): the same commands on the same states,
    and the same run."""
    from controllers.codegen import export_c
    from controllers.codegen.spatial_program import compiled_spatial_law
    from spatial_c_check import largest_command_difference

    law = _design([0.0, 5.0, 10.0], SpinUp(spin_rate=10.0, ramp_time=5.0))
    compiled = export_c(law, None, tmp_path / "c").compile()
    assert "scheduled over 3 spins" in compiled.program.description
    run = simulate_spatial_loop(CRAFT, 8.0, law, sample_time=0.05, n_modes=1,
                                variant="first_order", rtol=1e-9,
                                angular_velocity=(0.02, -0.01, 0.0)).result
    worst = largest_command_difference(law, compiled_spatial_law(compiled), run)
    assert worst < 1e-9 * np.abs(run.torque).max()
    flown = simulate_spatial_loop(CRAFT, 8.0, compiled_spatial_law(compiled), sample_time=0.05,
                                  n_modes=1, variant="first_order", rtol=1e-9,
                                  angular_velocity=(0.02, -0.01, 0.0)).result
    assert np.max(np.abs(flown.states - run.states)) < 1e-6
