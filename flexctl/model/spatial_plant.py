"""A spatial structure as a linear plant for control design (python-control ``StateSpace``).

:func:`linearize_spatial` linearises a spatial model
(:func:`~flexctl.model.spatial_dynamics.spatial_equations`: the exact rod by default, or its
first_order or zero_order expansion) about a straight structure turning steadily at
``angular_velocity`` (hub frame) from any attitude. The attitude is a three-parameter error:
the rotation vector ``e`` of ``q = q_ref (x) exp(e / 2)`` from the reference attitude that
turns at the same rate, whose rate is ``e_t = w - w_0 - w_0 x e`` to first order. A free hub's
position is left out (it moves nothing else); its velocity, in the hub frame, stays.

About the straight structure the exact and first_order plants are the same (first_order is the
exact equations to first order in the deflections, and a plant is first order); zero_order's
lacks the centrifugal stiffening, so that it equals theirs at rest only.

States ``ex, ey, ez``, the modal coordinates (``<name>.qn1``, ...), ``wx, wy, wz``, for a free
hub ``hub_vx, hub_vy, hub_vz``, and the modal rates; inputs ``tx, ty, tz`` (N m, hub frame);
outputs the attitude error, the angular velocity and every tip's displacement
(``<name>.tip_dx``, ...; hub frame, m). Names carry ``_`` for ``.`` (python-control keeps the
dot for ``system.signal``).

A straight structure turning about an axis that is not an equilibrium of it (an appendage
whose axis is not perpendicular to the spin, say, bends under the centrifugal load) is refused:
the straight state would be no operating point.
"""

from __future__ import annotations

import numpy as np

from .checks import check_array, check_choice, check_instance
from .errors import InputValueError
from .exports import signal_names
from .spatial_dynamics import SPATIAL_VARIANTS, spatial_equations, spatial_modes
from .spatial_rod import cross_matrix
from .spatial_structure import SpatialStructure

__all__ = ["linearize_spatial", "nonlinear_spatial", "EQUILIBRIUM_TOLERANCE"]

#: Largest modal acceleration of the straight, steadily turning structure, relative to its
#: centrifugal scale ``|w|^2 l``, for it to be an operating point.
EQUILIBRIUM_TOLERANCE = 1e-9


def linearize_spatial(structure: SpatialStructure, n_modes: int = 4,
                      angular_velocity=(0.0, 0.0, 0.0), variant: str = "exact"):
    """The linear plant of a spatial structure about a steady turn.

    Parameters
    ----------
    structure : SpatialStructure
        The hub and its appendages.
    n_modes : int, optional
        Modes per field of every appendage (1 to 12). Default 4.
    angular_velocity : array_like, shape (3,), optional
        The steady hub rate ``w_0`` in the hub frame, rad/s. Default zero (at rest).
    variant : {"exact", "first_order", "zero_order"}, optional
        The model linearised (:data:`~flexctl.model.spatial_dynamics.SPATIAL_VARIANTS`).
        Default ``"exact"``.

    Returns
    -------
    control.StateSpace
        See the module's description for its states, inputs and outputs.

    Raises
    ------
    InputValueError
        When the straight structure turning at ``w_0`` is not an equilibrium.

    Examples
    --------
    >>> import numpy as np
    >>> from flexctl import SpatialHub, SpatialAppendage, SpatialStructure
    >>> rod = SpatialAppendage(name="wing", direction=(1, 0, 0), normal=(0, 1, 0), length=1.8,
    ...                        density=2766.0, area=2.5e-4, youngs_modulus=6.9e10,
    ...                        second_moment=1.3e-10, second_moment_lateral=5.2e-8,
    ...                        shear_modulus=2.6e10, torsion_constant=5e-10)
    >>> plant = linearize_spatial(SpatialStructure(hub=SpatialHub(inertia=np.eye(3),
    ...                                            radius=0.06), appendages=(rod,)), n_modes=2)
    >>> plant.ninputs, plant.nstates, plant.input_labels
    (3, 18, ['tx', 'ty', 'tz'])
    """
    import casadi as ca
    import control

    check_instance("linearize_spatial", "structure", structure, SpatialStructure)
    n_modes = spatial_modes("linearize_spatial", structure, n_modes)
    w0 = np.array(check_array("linearize_spatial", "angular_velocity", angular_velocity,
                              shape=(3,)))
    if np.max(np.abs(w0)) > 1e4:
        raise InputValueError("linearize_spatial.angular_velocity must be at most 1e4 rad/s "
                              f"in magnitude; got {w0.tolist()}")
    variant = check_choice("linearize_spatial", "variant", variant, SPATIAL_VARIANTS)
    equations = spatial_equations(structure, n_modes, variant)
    layout = equations.layout
    x0 = np.zeros(layout.n_states)
    x0[0] = 1.0
    c = layout.n_coordinates
    x0[c:c + 3] = w0
    x = ca.SX.sym("x", layout.n_states)
    torque = ca.SX.sym("torque", 3)
    rate = equations.rhs(x, torque)
    _check_equilibrium(structure, equations, x0, w0)
    kept = _kept(layout)                     # the states of the plant, in the full state
    jac_x = ca.Function("jx", [x, torque], [ca.jacobian(rate, x), ca.jacobian(rate, torque),
                                            ca.jacobian(equations.tips(x), x)])
    full_a, full_b, full_c = (m.full() for m in jac_x(x0, np.zeros(3)))
    n = 3 + len(kept)
    a, b = np.zeros((n, n)), np.zeros((n, 3))
    # attitude error: e_t = w - w_0 - w_0 x e
    a[0:3, 0:3] = -cross_matrix(w0)
    a[0:3, 3 + kept.index(c):3 + kept.index(c) + 3] = np.eye(3)
    rows = kept
    a[3:, 3:] = full_a[np.ix_(rows, kept)]
    b[3:, :] = full_b[rows, :]
    names = ["ex", "ey", "ez"] + [layout.state_names[k] for k in kept]
    tips = [f"{name}.tip_{axis}" for name in structure.names for axis in ("dx", "dy", "dz")]
    c_tip = np.zeros((len(tips), n))
    c_tip[:, 3:] = full_c[:, kept]
    c_att = np.zeros((6, n))
    c_att[0:3, 0:3] = np.eye(3)
    c_att[3:6, 3 + kept.index(c):3 + kept.index(c) + 3] = np.eye(3)
    output = np.vstack([c_att, c_tip])
    outputs = ["ex", "ey", "ez", "wx", "wy", "wz", *tips]
    label = "_".join(f"{v:g}" for v in w0).replace(".", "p").replace("-", "m")
    return control.ss(a, b, output, np.zeros((output.shape[0], 3)),
                      states=signal_names(names), inputs=["tx", "ty", "tz"],
                      outputs=signal_names(outputs),
                      name=f"spatial_{variant}_N{n_modes}_w{label}")


def _kept(layout) -> list:
    """The full state's indices the plant keeps: the modal coordinates, the angular velocity,
    a free hub's velocity and the modal rates (not the quaternion, not the position)."""
    c = layout.n_coordinates
    modal = list(range(c - layout.n_elastic, c))
    return modal + list(range(c, layout.n_states))


def _check_equilibrium(structure, equations, x0, w0) -> None:
    rate = equations.rhs(x0, np.zeros(3)).full().ravel()
    layout = equations.layout
    modal = rate[-layout.n_elastic:]
    spin = rate[layout.n_coordinates:layout.n_coordinates + 3]
    scale = max(float(w0 @ w0) * max(a.length for a in structure.appendages), 1e-300)
    worst = max(float(np.max(np.abs(modal), initial=0.0)), float(np.max(np.abs(spin))))
    if worst > EQUILIBRIUM_TOLERANCE * scale and np.any(w0):
        raise InputValueError(
            f"linearize_spatial.angular_velocity {w0.tolist()} rad/s is no steady turn of the "
            f"straight structure: its accelerations reach {worst:.3g} (an appendage bent by the "
            "centrifugal load, or a spin about an axis that is not principal); linearize at "
            "rest or about a principal axis perpendicular to every appendage")


def nonlinear_spatial(structure: SpatialStructure, n_modes: int = 4, variant: str = "exact"):
    """A spatial model as a python-control ``NonlinearIOSystem``.

    Its right-hand side is the CasADi function
    :attr:`~flexctl.model.spatial_dynamics.SpatialEquations.rhs` (``(x, torque) -> x_dot``,
    itself the model's CasADi form), called on numbers.

    Parameters
    ----------
    structure : SpatialStructure
        The hub and its appendages.
    n_modes : int, optional
        Modes per field of every appendage (1 to 12). Default 4.
    variant : {"exact", "first_order", "zero_order"}, optional
        The model (:data:`~flexctl.model.spatial_dynamics.SPATIAL_VARIANTS`). Default
        ``"exact"``.

    Returns
    -------
    control.NonlinearIOSystem
        States :attr:`~flexctl.model.spatial_dynamics.SpatialLayout.state_names` (dots as
        ``_``), inputs ``tx, ty, tz`` (N m, hub frame), outputs the quaternion
        ``qw, qx, qy, qz``, the angular velocity ``wx, wy, wz`` and every tip's displacement
        (``<name>_tip_dx``, ...; hub frame, m).
    """
    import control

    check_instance("nonlinear_spatial", "structure", structure, SpatialStructure)
    n_modes = spatial_modes("nonlinear_spatial", structure, n_modes)
    variant = check_choice("nonlinear_spatial", "variant", variant, SPATIAL_VARIANTS)
    equations = spatial_equations(structure, n_modes, variant)
    layout = equations.layout
    c = layout.n_coordinates

    def update(t, x, u, params):
        return equations.rhs(x, u).full().ravel()

    def output(t, x, u, params):
        tips = equations.tips(x).full().ravel(order="F")
        return np.concatenate([x[0:4], x[c:c + 3], tips])

    tips = [f"{name}.tip_{axis}" for name in structure.names for axis in ("dx", "dy", "dz")]
    return control.nlsys(update, output, states=signal_names(layout.state_names),
                         inputs=["tx", "ty", "tz"],
                         outputs=signal_names(["qw", "qx", "qy", "qz", "wx", "wy", "wz",
                                               *tips]),
                         name=f"spatial_nonlinear_{variant}_N{n_modes}")
