"""A plant whose modes ring at other frequencies and damping ratios than the model says.

A flexible structure's modes are known to a few percent in frequency and to a factor in
damping. :func:`with_modes` returns the model with each coupled mode's frequency scaled by its
own factor and its damping ratio set, its mode shapes unchanged: the usual modal uncertainty
of a flexible spacecraft's sign-off, a frequency and a damping ratio per mode.

Notes
-----
The coupled modes are those of the structure with its hub free to turn (and, on a free hub,
to translate), about rest or a steady spin of a pinned hub: in the modal coordinates ``q``
(the hub's coordinates condensed out),

    K(Omega) v_k = lambda_k M_r v_k,    M_r = M_qq - M_qh M_hh^-1 M_hq,    V^T M_r V = I,

with ``lambda_k = omega_k^2`` (:meth:`Model.natural_frequencies` with ``hub="free"``). The
model returned has the modal stiffness and damping

    K'(Omega) = M_r V diag(f_k^2 lambda_k) V^T M_r,
    C' = M_r V diag(2 zeta_k f_k omega_k) V^T M_r,

so that its coupled frequencies are ``f_k omega_k``, its damping ratios ``zeta_k`` and its mode
shapes ``v_k`` (and so the torque's participation in each mode, and what each output sees of
it) the model's. The hub's rows of ``M v_k`` vanish (the modes are mass-orthogonal to the hub's
rigid motion), so the hub carries no stiffness or damping of the modes; its friction is kept.
The spin's part ``Omega^2 D`` of the stiffness is the model's, so ``K_ff' = K'(Omega) + Omega^2
D``: at another spin the modes are the perturbed structure's, not scaled again.

Examples
--------
>>> import numpy as np, flexctl
>>> model = flexctl.build_model(flexctl.load_scene("hub-beam-mass").system, n_modes=3)
>>> nominal = model.natural_frequencies(hub="free")
>>> stiffer = with_modes(model, frequency_factors=[1.0, 1.1, 0.9])
>>> np.round(stiffer.natural_frequencies(hub="free") / nominal, 12).tolist()
[1.0, 1.1, 0.9]
"""

from __future__ import annotations

import dataclasses

import numpy as np
import scipy.linalg

from .checks import check_real
from .errors import InputTypeError, InputValueError
from .variants import Model

__all__ = ["with_modes", "coupled_modes"]


def coupled_modes(model: Model, spin_rate: float = 0.0) -> tuple:
    """The coupled modes of ``model`` with its hub free (module Notes).

    Parameters
    ----------
    model : Model
        Any planar model (an actuated model's structure is used).
    spin_rate : float, optional
        Steady hub rate of a pinned hub, rad/s (0 for a free hub). Default 0.

    Returns
    -------
    lam : ndarray, shape (N,)
        ``omega_k^2``, (rad/s)^2, ascending (negative for a mode that has lost its stiffness).
    vectors : ndarray, shape (N, N)
        ``V``, M_r-orthonormal columns in the modal coordinates.
    reduced : ndarray, shape (N, N)
        ``M_r``, kg.
    """
    mech = _mechanical(model, "coupled_modes")
    mass = mech.rest_mass_matrix()
    n_modes = mech.matrices.n_modes
    n_h = mass.shape[0] - n_modes
    reduced = mass[n_h:, n_h:] - mass[n_h:, :n_h] @ np.linalg.solve(mass[:n_h, :n_h],
                                                                    mass[:n_h, n_h:])
    reduced = 0.5 * (reduced + reduced.T)
    stiffness = mech.stiffness_matrix(spin_rate)
    lam, vectors = scipy.linalg.eigh(0.5 * (stiffness + stiffness.T), reduced)
    return lam, vectors, reduced


def _mechanical(model, owner: str = "with_modes") -> Model:
    if not isinstance(model, Model):
        raise InputTypeError(f"{owner}.model must be a planar flexctl Model; got "
                             f"{type(model).__name__}")
    return model.mechanical if hasattr(model, "mechanical") else model


def _per_mode(name: str, values, n_modes: int, maximum: float, strict: bool) -> np.ndarray:
    array = np.asarray(values, dtype=object).reshape(-1)
    if array.size == 1:
        array = np.repeat(array, n_modes)
    if array.size != n_modes:
        raise InputValueError(f"with_modes.{name} must be one number or one per mode "
                              f"({n_modes}); got {array.size}")
    return np.array([check_real("with_modes", name, v, minimum=0.0, maximum=maximum,
                                strict=strict) for v in array])


def with_modes(model: Model, frequency_factors=1.0, damping_ratios=None,
               spin_rate: float = 0.0) -> Model:
    """``model`` with its coupled modes' frequencies scaled and damping ratios set (module
    Notes).

    Parameters
    ----------
    model : Model
        A planar model of :func:`flexctl.build_model` (an actuated one included: its
        structure's modes are changed, the actuator kept).
    frequency_factors : float or array_like, shape (N,), optional
        Factor on each coupled mode's frequency, in (0, 100]; one number scales them all.
        Default 1.
    damping_ratios : float or array_like, shape (N,), optional
        Each coupled mode's damping ratio, in [0, 1); one number sets them all. Default: the
        model's own modal damping, unchanged (with the frequencies changed, its ratios change).
    spin_rate : float, optional
        Steady hub rate of a pinned hub at which the modes are the coupled ones, rad/s (0 for a
        free hub). Default 0.

    Returns
    -------
    Model
        Of the same class, variant, modes (and actuator) as ``model``.

    Raises
    ------
    InputValueError
        For a factor or ratio out of range, a count that is not the number of modes, or a
        mode that has no stiffness at ``spin_rate`` (nothing to scale).
    """
    mech = _mechanical(model)
    spin_rate = check_real("with_modes", "spin_rate", spin_rate, minimum=-1e100, maximum=1e100)
    n_modes = mech.matrices.n_modes
    factors = _per_mode("frequency_factors", frequency_factors, n_modes, 100.0, True)
    lam, vectors, reduced = coupled_modes(mech, spin_rate)
    if np.any(lam <= 0.0):
        k = int(np.flatnonzero(lam <= 0.0)[0]) + 1
        raise InputValueError(f"with_modes: coupled mode {k} has no stiffness at spin_rate "
                              f"= {spin_rate:g} rad/s (omega^2 = {lam[k - 1]:.4g}); its "
                              "frequency cannot be scaled")
    shape = reduced @ vectors
    omega = factors * np.sqrt(lam)
    stiffness = shape @ np.diag(omega ** 2) @ shape.T
    matrices = mech.matrices
    # the spin's part of the stiffness, Omega^2 D, is the model's
    stiff_ff = 0.5 * (stiffness + stiffness.T) + (matrices.K_ff
                                                  - mech.stiffness_matrix(spin_rate))
    if damping_ratios is None:
        damping = matrices.C_ff
    else:
        zeta = _per_mode("damping_ratios", damping_ratios, n_modes, 0.999, False)
        damping = shape @ np.diag(2.0 * zeta * omega) @ shape.T
        damping = 0.5 * (damping + damping.T)
    for array in (stiff_ff, damping):
        array.setflags(write=False)
    changed = dataclasses.replace(matrices, K_ff=stiff_ff, C_ff=damping)
    return dataclasses.replace(model, matrices=changed)
