"""Which modes of a spatial structure at rest each torque axis moves and each output sees.

The undamped modes of the exact spatial model linearised about rest
(:func:`~flexctl.model.spatial_dynamics.spatial_equations`): its mass matrix ``M`` in the speeds
``(w, [v_h], modal rates)`` (:class:`~flexctl.model.spatial_dynamics.SpatialLayout`), the
stiffness ``K`` of the modal coordinates (``-M`` times the accelerations' Jacobian in them; the
attitude and a free hub's position have none), and the hub torque's generalized forces (the
``w`` rows). The conjugate coordinates are the attitude error ``e`` (the rotation vector of
:func:`~flexctl.model.spatial_plant.linearize_spatial`), a free hub's position ``r`` (hub frame)
and the modal coordinates; the outputs are the attitude error, the angular velocity and every
tip's three components, as the linear plant's. The shares are those of
:func:`flexctl.model.visibility.visibility_of`.

Only rest is taken: a turning structure's modes are gyroscopic (complex, not the real shapes of
a symmetric eigenproblem).

Examples
--------
Two equal arrays on opposite sides bending together along z leave the hub's rows unforced: no
torque moves that mode.

>>> import numpy as np
>>> from flexctl import SpatialAppendage, SpatialHub, SpatialStructure
>>> from flexctl.model.spatial_visibility import spatial_modal_visibility
>>> def wing(name, sign):
...     return SpatialAppendage(name=name, direction=(sign, 0, 0), normal=(0, 0, 1), length=1.8,
...                             density=2766.0, area=2.5e-4, youngs_modulus=6.9e10,
...                             second_moment=1.3e-10, second_moment_lateral=5.2e-8,
...                             shear_modulus=2.6e10, torsion_constant=5e-10)
>>> craft = SpatialStructure(hub=SpatialHub(inertia=np.diag([1.0, 1.2, 1.4]), radius=0.06),
...                          appendages=(wing("a", 1.0), wing("b", -1.0)))
>>> report = spatial_modal_visibility(craft, n_modes=1)
>>> len(set(report.uncontrollable("tx")) & set(report.uncontrollable("ty"))
...     & set(report.uncontrollable("tz"))) > 0
True
"""

from __future__ import annotations

import numpy as np

from .checks import check_instance
from .spatial_dynamics import spatial_equations, spatial_modes
from .spatial_structure import SpatialStructure
from .visibility import ModalVisibility, visibility_of

__all__ = ["spatial_modal_visibility"]


def spatial_modal_visibility(structure: SpatialStructure, n_modes: int = 4) -> ModalVisibility:
    """The :class:`~flexctl.model.visibility.ModalVisibility` of a spatial structure at rest.

    Parameters
    ----------
    structure : SpatialStructure
        The structure (pinned or free hub).
    n_modes : int, optional
        Modes per field of every appendage (1 to 12). Default 4.

    Returns
    -------
    ModalVisibility
        Inputs ``tx, ty, tz`` (N m, hub frame); outputs ``ex, ey, ez, wx, wy, wz`` and
        ``<name>.tip_dx, <name>.tip_dy, <name>.tip_dz`` per appendage; coordinates ``ex, ey,
        ez``, for a free hub ``hub_x, hub_y, hub_z``, then the modal coordinates. The rigid
        modes have frequency 0.
    """
    import casadi as ca

    check_instance("spatial_modal_visibility", "structure", structure, SpatialStructure)
    n_modes = spatial_modes("spatial_modal_visibility", structure, n_modes)
    equations = spatial_equations(structure, n_modes)
    layout = equations.layout
    rest = np.zeros(layout.n_states)
    rest[0] = 1.0
    c, n_el = layout.n_coordinates, layout.n_elastic
    elastic = slice(c - n_el, c)
    x = ca.SX.sym("x", layout.n_states)
    jacobians = ca.Function("rest", [x], [ca.jacobian(equations.rhs(x, np.zeros(3)), x),
                                          ca.jacobian(equations.tips(x), x)])
    rate_jacobian, tip_jacobian = (m.full() for m in jacobians(rest))
    mass = equations.mass_matrix(rest).full()
    n_u = layout.n_speeds
    stiffness = np.zeros((n_u, n_u))
    stiffness[:, n_u - n_el:] = -mass @ rate_jacobian[c:, elastic]
    load = np.zeros((n_u, 3))
    load[0:3, :] = np.eye(3)
    tips = tip_jacobian[:, elastic]
    n_out = 6 + tips.shape[0]
    c_position, c_rate = np.zeros((n_out, n_u)), np.zeros((n_out, n_u))
    c_position[0:3, 0:3] = np.eye(3)                    # the attitude error
    c_rate[3:6, 0:3] = np.eye(3)                        # the angular velocity
    c_position[6:, n_u - n_el:] = tips
    hub = ("ex", "ey", "ez") + (("hub_x", "hub_y", "hub_z") if n_u - n_el == 6 else ())
    tip_names = tuple(f"{name}.tip_{axis}" for name in structure.names
                      for axis in ("dx", "dy", "dz"))
    return visibility_of(mass, stiffness, load, c_position, c_rate,
                         coordinates=hub + tuple(layout.state_names[elastic]),
                         inputs=("tx", "ty", "tz"),
                         outputs=("ex", "ey", "ez", "wx", "wy", "wz") + tip_names)
