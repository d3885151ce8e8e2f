"""Checks of the independent geometrically exact reference simulator ``fe_reference``.

The reference (rigid finite elements, exact planar kinematics) is checked against closed-form
results only, never against flexctl: the clamped-free frequency, the centrifugal stiffening of
a spinning beam, conservation of energy and angular momentum, and mesh convergence. It also
prints the peak tip deflections of the reference manoeuvres of MODEL.md sections 5-6.
"""

import functools
import os
import sys

import numpy as np
import pytest

sys.path.insert(0, os.path.dirname(__file__))

from fe_reference import (FESystem, convergence_study, simulate_fe,  # noqa: E402
                          sine_torque, spin_up_motion)

Z1 = 1.8751041          # first root of cos z cosh z + 1 = 0
SOUTHWELL_1 = 1.1933    # first Southwell coefficient at b = 0

#: a modest unit beam: l = 1 m, rhoA = 1 kg/m, EI = 1 N m^2 (omega_1 = 3.516 rad/s)
UNIT_BEAM = FESystem(hub_inertia=0.0, hub_radius=0.0, length=1.0, linear_density=1.0,
                     bending_stiffness=1.0)

E_AL = 6.8952e10
#: MODEL.md section 6: Kane, Ryan and Banerjee's beam, hub radius 0, hub motion prescribed
KANE = FESystem(0.0, 0.0, 8.0, 2766.67 * 7.2968e-5, E_AL * 8.2189e-9)
#: MODEL.md section 6: paper 001 spacecraft, massless hub
SPACECRAFT = FESystem(0.0, 0.0, 5.0, 2766.7 * 4e-4, E_AL * 1.333e-8)
#: MODEL.md section 6: paper 000 hub-beam-mass system, 0.085 kg at 0.9 l
HUB_BEAM_MASS = FESystem(1.16, 0.06, 1.8, 2766 * 2.5e-4, 6.9e10 * 1.3021e-10,
                         masses=((0.085, 0.9 * 1.8),))


def clamped_mode_slope(s, length, z=Z1):
    """Slope ``phi_1'(s)`` of the first clamped-free mode (normalized to tip value 2)."""
    xi = np.asarray(s) / length
    sig = (np.cosh(z) + np.cos(z)) / (np.sinh(z) + np.sin(z))
    return z / length * (np.sinh(z * xi) + np.sin(z * xi)
                         - sig * (np.cosh(z * xi) - np.cos(z * xi)))


def measured_frequency(t, y):
    """Angular frequency from the upward zero crossings of ``y(t)`` (least-squares period)."""
    i = np.nonzero((y[:-1] < 0.0) & (y[1:] >= 0.0))[0]
    tc = t[i] - y[i] * (t[i + 1] - t[i]) / (y[i + 1] - y[i])
    assert len(tc) >= 4, "too few periods"
    period = np.polyfit(np.arange(len(tc)), tc, 1)[0]
    return 2.0 * np.pi / period


def still(t):
    return 0.0, 0.0, 0.0


def test_small_amplitude_clamped_frequency():
    """Hub held still, small first-mode deflection: the period is the clamped-free one."""
    beam = UNIT_BEAM
    omega_0 = Z1 ** 2 * np.sqrt(beam.bending_stiffness / (beam.linear_density * beam.length ** 4))
    amp = 5e-4       # tip deflection 1e-3 l
    r = simulate_fe(beam, 8 * 2 * np.pi / omega_0, hub_motion=still, n_elements=24,
                    initial_slope=lambda s: amp * clamped_mode_slope(s, beam.length))
    omega = measured_frequency(r["t"], r["tip_deflection"])
    print(f"\nclamped-free: omega = {omega:.6f} rad/s, exact {omega_0:.6f}, "
          f"error {omega / omega_0 - 1:+.2e} (24 elements, cpu {r['cpu_time']:.1f} s)")
    assert abs(omega / omega_0 - 1.0) < 0.005


def test_tip_mass_frequency():
    """MODEL.md section 6: tip mass with R_M = 1 on the paper-000 beam, exact 1.7325 rad/s."""
    beam = HUB_BEAM_MASS
    system = FESystem(0.0, beam.hub_radius, beam.length, beam.linear_density,
                      beam.bending_stiffness, masses=((beam.linear_density * beam.length,
                                                       beam.length),))
    r = simulate_fe(system, 6 * 2 * np.pi / 1.7325, hub_motion=still, n_elements=24,
                    initial_slope=lambda s: 1e-3 * clamped_mode_slope(s, beam.length))
    omega = measured_frequency(r["t"], r["tip_deflection"])
    print(f"\ntip mass R_M = 1: omega = {omega:.5f} rad/s, exact 1.7325 "
          f"(error {omega / 1.7325 - 1:+.1e})")
    assert abs(omega / 1.7325 - 1.0) < 0.005


def test_positive_torque_bends_tip_to_negative_y():
    """Sign convention of MODEL.md section 1, and the hub turns the positive way."""
    r = simulate_fe(HUB_BEAM_MASS, 0.3, torque=sine_torque(2.0, 2.0), n_elements=12)
    assert r["tip_deflection"][-1] < 0.0
    assert r["theta"][-1] > 0.0 and r["theta_dot"][-1] > 0.0
    assert np.all(r["tip_foreshortening"] >= -1e-12)


def test_centrifugal_stiffening_southwell():
    """Steady prescribed spin at b = 0: the first in-plane frequency in the hub frame.

    For in-plane (lead-lag) bending the tension stiffening ``K_1 Omega^2`` (Southwell's
    ``K_1 = 1.1933``) comes with the centrifugal softening ``-Omega^2`` of the lateral motion
    (MODEL.md section 2: ``a_y = y_tt + ... - theta_t^2 y``), so
    ``omega^2 = omega_0^2 + (K_1 - 1) Omega^2``. ``K_1 Omega^2`` alone is the out-of-plane
    (flapping) result, which the planar model cannot show.
    """
    beam = UNIT_BEAM
    omega_0 = Z1 ** 2 * np.sqrt(beam.bending_stiffness / (beam.linear_density * beam.length ** 4))
    spin = 3.0 * np.sqrt(beam.bending_stiffness / (beam.linear_density * beam.length ** 4))
    expected = np.sqrt(omega_0 ** 2 + (SOUTHWELL_1 - 1.0) * spin ** 2)
    r = simulate_fe(beam, 8 * 2 * np.pi / expected, n_elements=24,
                    hub_motion=lambda t: (spin * t, spin, 0.0),
                    initial_slope=lambda s: 5e-4 * clamped_mode_slope(s, beam.length))
    omega = measured_frequency(r["t"], r["tip_deflection"])
    print(f"\nspinning at {spin:.3f} rad/s: omega = {omega:.6f} rad/s, Southwell in-plane "
          f"{expected:.6f} (error {omega / expected - 1:+.2e}); non-rotating {omega_0:.6f}, "
          f"out-of-plane formula {np.sqrt(omega_0 ** 2 + SOUTHWELL_1 * spin ** 2):.6f}, "
          f"no stiffening {np.sqrt(omega_0 ** 2 - spin ** 2):.6f}")
    assert abs(omega / expected - 1.0) < 0.01


def test_energy_and_momentum_conserved_free_run():
    """Massless hub, free and unforced, 30 % initial tip deflection, spinning, two masses."""
    system = FESystem(0.0, 0.1, 1.0, 1.0, 1.0, masses=((0.3, 0.5), (0.2, 1.0)))
    def slope(s):                                # tip-load shape
        return 0.47 * (2.0 * s - s * s)
    r = simulate_fe(system, 6.0, n_elements=24, initial_slope=slope, initial_theta_dot=2.0)
    y0 = r["tip_deflection"][0]
    e, h = r["energy"], r["angular_momentum"]
    de = np.max(np.abs(e - e[0])) / e[0]
    dh = np.max(np.abs(h - h[0])) / abs(h[0])
    print(f"\nfree run: initial tip deflection {y0:.4f} m (foreshortening "
          f"{r['tip_foreshortening'][0]:.4f} m), min/max tip {r['tip_deflection'].min():.4f}/"
          f"{r['tip_deflection'].max():.4f} m, hub turned {r['theta'][-1]:.3f} rad; "
          f"relative drift: energy {de:.1e}, angular momentum {dh:.1e}")
    assert abs(y0) > 0.29
    assert np.ptp(r["theta_dot"]) > 0.5          # a strongly coupled motion
    assert de < 1e-5
    assert dh < 1e-5


@functools.lru_cache(maxsize=None)
def peak_run(case: str, n_elements: int):
    """Peak tip deflection (signed), its time, max foreshortening and cpu time of a case."""
    system, t_final, drive = CASES[case]
    r = simulate_fe(system, t_final, n_elements=n_elements, **drive)
    y = r["tip_deflection"]
    k = int(np.argmax(np.abs(y)))
    return y[k], r["t"][k], r["tip_foreshortening"].max(), r["cpu_time"]


CASES = {
    "Kane spin-up to 10 rad/s, T_s = 15 s (20 s)":
        (KANE, 20.0, dict(hub_motion=spin_up_motion(10.0, 15.0))),
    "spacecraft, 50 N m sine over 2 s (6 s)":
        (SPACECRAFT, 6.0, dict(torque=sine_torque(50.0, 2.0))),
    "hub-beam-mass, 2 N m sine over 2 s (6 s)":
        (HUB_BEAM_MASS, 6.0, dict(torque=sine_torque(2.0, 2.0))),
}
PUBLISHED = dict(zip(CASES, (1.09, 0.42, 0.263)))   # first-order values, for orientation


@pytest.mark.slow
def test_mesh_convergence_spacecraft():
    """MODEL.md section 6 spacecraft case: the peak tip deflection is mesh-converged."""
    case = "spacecraft, 50 N m sine over 2 s (6 s)"
    elements = (16, 32, 64)
    peaks = np.array([abs(peak_run(case, n)[0]) for n in elements])
    changes = np.abs(np.diff(peaks)) / peaks[1:]
    print("\nspacecraft peak tip deflection: "
          + ", ".join(f"{n} el: {p:.6f} m" for n, p in zip(elements, peaks))
          + "; changes " + ", ".join(f"{c:.2e}" for c in changes)
          + "; cpu " + ", ".join(f"{peak_run(case, n)[3]:.1f} s" for n in elements))
    assert changes[-1] < 1e-3
    assert changes[-1] < 0.5 * changes[0]     # second-order convergence shows


@pytest.mark.slow
def test_print_reference_peaks():
    """Peak tip deflections of the reference manoeuvres (printed, only sanity-checked).

    Printed for 16 and 32 elements and Richardson-extrapolated (the method is O(h^2)); the
    64-element runs are in :func:`test_mesh_convergence_spacecraft`.
    """
    print()
    for case in CASES:
        (y16, _, _, c16), (y32, t32, f32, c32) = peak_run(case, 16), peak_run(case, 32)
        extrapolated = y32 + (y32 - y16) / 3.0
        print(f"{case}: peak tip {y16:+.5f} m (16 el, cpu {c16:.1f} s), {y32:+.5f} m at "
              f"t = {t32:.3f} s (32 el, cpu {c32:.1f} s), extrapolated {extrapolated:+.5f} m; "
              f"max foreshortening {f32:.5f} m; first-order published about {PUBLISHED[case]}")
        assert abs(abs(extrapolated) / PUBLISHED[case] - 1.0) < 0.05


def test_convergence_helper_small():
    """The convergence helper runs and reports decreasing changes (tiny, fast case)."""
    study = convergence_study(UNIT_BEAM, 1.0, elements=(4, 8, 16),
                              hub_motion=spin_up_motion(3.0, 1.0))
    assert study["peaks"].shape == (3,) and np.all(study["peaks"] > 0.0)
    assert study["changes"][1] < study["changes"][0]
