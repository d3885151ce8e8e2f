"""Reduced design models of a linearised plant: modal and balanced truncation, with their error.

A plant ``G(s) = D + C (sI - A)^-1 B`` (a python-control ``StateSpace``, or a flexctl model
linearised about a steady spin) becomes a plant ``G_r`` of fewer states, and the
:class:`Reduction` says by how much they differ: ``||G - G_r||_inf``, the largest singular
value of ``G(jw) - G_r(jw)`` over all frequencies ``w``, in the outputs' units per input unit
(N m for the torque).

- :func:`modal_truncation` keeps the rigid-body part and the flexible modes up to a count or
  a frequency, in real modal coordinates, and states the H_inf norm of the discarded part
  (which is the error itself), optionally after a static correction that keeps the
  discarded modes' quasi-static response.
- :func:`balanced_truncation` keeps the rigid-body part whole and balances the stable rest
  (square-root method, SciPy only); the a priori bound is twice the sum of the discarded
  Hankel singular values.
- :func:`hinf_norm` computes the H_inf norm of a stable plant without slycot.

Notes
-----
The poles ``p`` of ``A`` fall into three groups, read from the plant, never from its names
(the hub couples the beam's coordinates, so ``A`` is not block-diagonal in them):

- rigid-body: ``|p| <= 100 sqrt(eps max(1, ||A||_1))`` (the hub's double integrator, a free
  hub's translation: a double pole at 0 is computed to ``sqrt(eps ||A||)``);
- real: the other real poles (hub friction, an actuator's lag): always kept;
- flexible modes: complex pairs, numbered ``mode1, mode2, ..`` by natural frequency ``|p|``.

The groups are separated by an ordered real Schur form and a Sylvester equation (a
block-diagonalising similarity), which stays exact for the rigid body's Jordan block.
The reduced states are named ``rigid1..``, ``real1..`` (a real Schur basis of each group)
and, for each kept mode, ``modeJ``
and ``modeJ_dot``: a coordinate that obeys ``eta'' + 2 zeta w eta' + w^2 eta = u`` for a plant
with one input (the input enters each mode with unit gain). Balanced states are
``balanced1..`` in decreasing Hankel singular value. Inputs and outputs keep their names.

Examples
--------
>>> from flexctl import build_model, load_scene
>>> from flexctl.model.reduction import modal_truncation
>>> scene = load_scene("hub-beam-mass", {"beam.damping_ratio": 0.01})
>>> model = build_model(scene.system, n_modes=6)
>>> reduced = modal_truncation(model, 2)
>>> reduced.kept, reduced.system.nstates
(('rigid', 'mode1', 'mode2'), 6)
>>> reduced.system.state_labels
['rigid1', 'rigid2', 'mode1', 'mode1_dot', 'mode2', 'mode2_dot']
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
import scipy.linalg

from .checks import check_choice, check_instance, check_integer, check_real
from .errors import InputTypeError, InputValueError

__all__ = ["Reduction", "modal_truncation", "balanced_truncation", "hinf_norm", "METHODS",
           "NORM_RTOL"]

#: The reductions a :class:`Reduction` can come from.
METHODS = ("modal truncation", "modal truncation with static correction", "balanced truncation")
#: Relative tolerance of :func:`hinf_norm`; the value returned is rounded up by it.
NORM_RTOL = 1e-7
#: A complex pair whose damping ratio is below this is on the imaginary axis (undamped).
MARGINAL_DAMPING = 1e-9
#: Two poles closer than this (relative) are one: modal truncation cannot cut between them.
COINCIDENT_POLES = 1e-6
#: Hankel singular values below this fraction of the largest are zero: the Gramians carry an
#: error of about eps times their norm, so the square-root factors about sqrt(eps) = 1.5e-8.
HSV_FLOOR = 1e-8


@dataclass(frozen=True, kw_only=True, eq=False)
class Reduction:
    """A reduced plant and how far it is from the full one.

    Attributes
    ----------
    system : control.StateSpace
        The reduced plant ``G_r``: ``r`` states (named as in :mod:`flexctl.model.reduction`),
        the inputs and outputs of the full plant.
    method : str
        One of :data:`METHODS`.
    error : float
        ``||G - G_r||_inf`` computed by :func:`hinf_norm` (rounded up by :data:`NORM_RTOL`);
        ``inf`` when an undamped mode is discarded. Units: the outputs' per input unit.
    error_bound : float
        The method's guaranteed bound on ``||G - G_r||_inf``, ``>= error``: for modal
        truncation the computed norm of the discarded part itself (it has no a priori bound),
        for balanced truncation ``2 * sum`` of the discarded Hankel singular values.
    kept, discarded : tuple of str
        The parts kept and left out: ``"rigid"``, ``"real"``, ``"mode1"``, .. or
        ``"balanced1"``, ...
    discarded_poles : ndarray of complex, shape (n - r,)
        Poles of the discarded modes, rad/s, by natural frequency (empty for balanced
        truncation: balanced states are not modes).
    hankel_singular_values : ndarray, shape (n_stable,)
        Of the stable part, decreasing (empty for modal truncation).
    """

    system: object
    method: str
    error: float
    error_bound: float
    kept: tuple
    discarded: tuple
    discarded_poles: np.ndarray = field(default_factory=lambda: np.zeros(0, dtype=complex))
    hankel_singular_values: np.ndarray = field(default_factory=lambda: np.zeros(0))

    def __post_init__(self):
        import control

        check_instance("Reduction", "system", self.system, control.StateSpace,
                       "control.StateSpace")
        check_choice("Reduction", "method", self.method, METHODS)
        for name in ("error", "error_bound"):
            value = getattr(self, name)
            if value != float("inf"):
                value = check_real("Reduction", name, value, minimum=0.0)
            object.__setattr__(self, name, float(value))
        for name in ("kept", "discarded"):
            parts = tuple(getattr(self, name))
            if not all(isinstance(part, str) for part in parts):
                raise InputTypeError(f"Reduction.{name} must be names (str); got {parts!r}")
            object.__setattr__(self, name, parts)
        for name, kind in (("discarded_poles", complex), ("hankel_singular_values", float)):
            array = np.array(getattr(self, name), dtype=kind).reshape(-1)
            array.setflags(write=False)
            object.__setattr__(self, name, array)

    def __repr__(self):
        return (f"Reduction({self.method}, {self.system.nstates} states kept, "
                f"{len(self.discarded)} parts discarded, error {self.error:.3g} <= bound "
                f"{self.error_bound:.3g})")


# ------------------------------------------------------------------ the plant and its parts
def _plant(owner: str, model_or_sys, spin_rate, name: str = "model_or_sys"):
    """The plant as a continuous-time ``StateSpace`` with finite matrices (a model is
    linearised about ``spin_rate``; ``name`` ``"system"`` takes a ``StateSpace`` only)."""
    import control

    from .variants import Model

    if name == "system":
        check_instance(owner, name, model_or_sys, control.StateSpace, "control.StateSpace")
    else:
        check_instance(owner, name, model_or_sys, (Model, control.StateSpace),
                       "flexctl Model or a control.StateSpace")
    spin_rate = check_real(owner, "spin_rate", spin_rate)
    if isinstance(model_or_sys, Model):
        return model_or_sys.linearize(spin_rate)
    if spin_rate != 0.0:
        raise InputValueError(f"{owner}.spin_rate must be 0 for a StateSpace (it is already "
                              f"linearised; spin_rate applies to a flexctl model); got "
                              f"{spin_rate!r}")
    if not model_or_sys.isctime():
        raise InputValueError(f"{owner}.{name} must be a continuous-time system; got "
                              f"sample time dt={model_or_sys.dt!r}")
    if model_or_sys.nstates == 0:
        raise InputValueError(f"{owner}.{name} must have states; got a static gain (0 states)")
    matrices = (model_or_sys.A, model_or_sys.B, model_or_sys.C, model_or_sys.D)
    if not all(np.all(np.isfinite(m)) for m in matrices):
        raise InputValueError(f"{owner}.{name} must have finite A, B, C, D; got a NaN or an "
                              "infinity")
    return model_or_sys


class _Poles:
    """The groups of the poles of ``A`` (see the module's Notes)."""

    def __init__(self, a):
        eps, size = np.finfo(float).eps, max(1.0, np.linalg.norm(a, 1))
        # a rigid body's double pole at 0 comes out as +-sqrt(eps ||A||) at worst
        self.zero_tol = 100.0 * np.sqrt(eps * size)
        self.round_off = 1e3 * eps * size
        self.all = np.linalg.eigvals(a)

    def rigid(self, p):
        return abs(p) <= self.zero_tol

    def oscillatory(self, p):
        return not self.rigid(p) and abs(p.imag) > COINCIDENT_POLES * abs(p)

    def marginal(self, p):
        """On or right of the imaginary axis, to the precision of the poles."""
        return self.rigid(p) or p.real >= -MARGINAL_DAMPING * abs(p)

    def stable(self):
        """All poles left of the imaginary axis by more than their round-off."""
        return bool(np.all(self.all.real < -np.maximum(MARGINAL_DAMPING * np.abs(self.all),
                                                       self.round_off)))

    def pairs(self):
        """One pole of each flexible mode (positive imaginary part), by natural frequency."""
        upper = [p for p in self.all if self.oscillatory(p) and p.imag > 0]
        return sorted(upper, key=abs)


def _near(poles):
    """A selector of the poles ``p`` within :data:`COINCIDENT_POLES` of ``poles`` or their
    conjugates."""
    targets = np.concatenate([np.asarray(poles, dtype=complex), np.conj(poles)])
    return lambda p: bool(np.any(np.abs(targets - p) <= COINCIDENT_POLES * np.abs(targets)))


def _peel(a, b, c, select):
    """``(a1, b1, c1), (a2, b2, c2)``: the parts of ``(a, b, c)`` whose poles ``select`` picks
    and the rest, decoupled by an ordered real Schur form and a Sylvester equation."""
    n = a.shape[0]
    wanted = sum(bool(select(p)) for p in np.linalg.eigvals(a)) if n else 0
    if wanted in (0, n):
        empty = (np.zeros((0, 0)), np.zeros((0, b.shape[1])), np.zeros((c.shape[0], 0)))
        whole = (a, b, c)
        return (whole, empty) if wanted == n else (empty, whole)
    t, z, sdim = scipy.linalg.schur(a, output="real", sort=lambda re, im: select(complex(re, im)))
    if sdim != wanted:
        raise np.linalg.LinAlgError(f"the Schur reordering selected {sdim} poles instead of "
                                    f"{wanted}; the plant's poles are too close to separate")
    k = sdim
    x = scipy.linalg.solve_sylvester(t[:k, :k], -t[k:, k:], -t[:k, k:])
    bz, cz = z.T @ b, c @ z
    first = (t[:k, :k], bz[:k] - x @ bz[k:], cz[:, :k])
    rest = (t[k:, k:], bz[k:], cz[:, :k] @ x + cz[:, k:])
    return first, rest


def _join(blocks, plant):
    """``(a, b, c)`` of the decoupled ``blocks`` side by side (shapes (r, r), (r, m), (p, r))."""
    blocks = [blk for blk in blocks if blk[0].shape[0]]
    if not blocks:
        return (np.zeros((0, 0)), np.zeros((0, plant.ninputs)), np.zeros((plant.noutputs, 0)))
    return (scipy.linalg.block_diag(*[blk[0] for blk in blocks]),
            np.vstack([blk[1] for blk in blocks]), np.hstack([blk[2] for blk in blocks]))


def _companion(a, b, c):
    """A 2-state mode in the coordinates ``(eta, eta_dot)``: ``a = [[0, 1], [-w^2, -2 zeta w]]``;
    for one input ``b = [0, 1]``."""
    w = np.array([1.0, 0.0])
    if b.shape[1] == 1 and np.linalg.norm(b) > 0:
        w = np.array([-b[1, 0], b[0, 0]])     # eta does not see the input: it enters eta''
        w = w / (w @ a @ b[:, 0])
    t = np.vstack([w, w @ a])
    t_inv = np.linalg.inv(t)
    return t @ a @ t_inv, t @ b, c @ t_inv


# ------------------------------------------------------------------ modal truncation
def _kept_pair_count(owner, pairs, n_modes, max_frequency):
    if (n_modes is None) == (max_frequency is None):
        raise InputValueError(f"{owner} needs exactly one of n_modes and max_frequency; got "
                              f"n_modes={n_modes!r}, max_frequency={max_frequency!r}")
    if n_modes is not None:
        return check_integer(owner, "n_modes", n_modes, minimum=0, maximum=len(pairs))
    limit = check_real(owner, "max_frequency", max_frequency, minimum=0.0, strict=True)
    return sum(abs(p) <= limit for p in pairs)


def modal_truncation(model_or_sys, n_modes=None, *, max_frequency=None, keep_dc_gain=False,
                     spin_rate=0.0) -> Reduction:
    """The rigid-body part and the lowest flexible modes of a plant, in modal coordinates.

    Parameters
    ----------
    model_or_sys : Model or control.StateSpace
        A flexctl model (linearised about ``spin_rate``) or a continuous-time plant.
    n_modes : int, optional
        How many flexible modes (complex pole pairs, by natural frequency) to keep,
        ``0 <= n_modes <=`` the plant's number of modes.
    max_frequency : float, optional
        Or keep the modes of natural frequency ``|p| <= max_frequency``, rad/s, ``> 0``.
    keep_dc_gain : bool, optional
        Add the discarded modes' static gain ``-C_d A_d^-1 B_d`` to ``D`` (static correction,
        the residualisation of the fast modes): the reduced plant keeps their quasi-static
        response, e.g. the beam's steady bending under a steady hub acceleration.
    spin_rate : float, optional
        Steady hub rate, rad/s, for a model (0 for a ``StateSpace``).

    Returns
    -------
    Reduction
        ``system`` with ``n_rigid + n_real + 2 * n_kept`` states (``rigid1..``, ``real1..``,
        ``modeJ``, ``modeJ_dot``); ``error = error_bound = ||G_d||_inf`` (``||G_d - G_d(0)||``
        with ``keep_dc_gain``), the exact H_inf norm of the discarded part ``G_d`` by
        :func:`hinf_norm`, since ``G = G_r + G_d``; ``inf`` if a discarded mode is undamped.

    Raises
    ------
    InputTypeError, InputValueError
        For a wrong argument (named with its rule and value), both or neither of ``n_modes``
        and ``max_frequency``, or a cut between two modes of equal poles.

    Examples
    --------
    >>> from flexctl import build_model, load_scene
    >>> model = build_model(load_scene("hub-beam-mass").system, n_modes=4)
    >>> reduced = modal_truncation(model, max_frequency=30.0)
    >>> reduced.kept, reduced.discarded, reduced.error    # undamped beam: infinite peak
    (('rigid', 'mode1', 'mode2'), ('mode3', 'mode4'), inf)
    """
    import control

    owner = "modal_truncation"
    plant = _plant(owner, model_or_sys, spin_rate)
    check_instance(owner, "keep_dc_gain", keep_dc_gain, bool)
    poles = _Poles(plant.A)
    pairs = poles.pairs()
    n_kept = _kept_pair_count(owner, pairs, n_modes, max_frequency)
    if 0 < n_kept < len(pairs) and _near(pairs[n_kept - 1:n_kept])(pairs[n_kept]):
        raise InputValueError(f"{owner}.n_modes (or max_frequency) must not separate modes "
                              f"{n_kept} and {n_kept + 1}, which have the same poles "
                              f"({pairs[n_kept]:.6g}); got {n_kept} modes kept: keep both or "
                              "neither")
    rigid, rest = _peel(plant.A, plant.B, plant.C, poles.rigid)
    real, rest = _peel(*rest, lambda p: not poles.oscillatory(p))
    kept, dropped = _peel(*rest, _near(pairs[:n_kept]))
    blocks, names, states = _mode_blocks(kept, pairs[:n_kept])
    for block, name in ((real, "real"), (rigid, "rigid")):
        if block[0].shape[0]:
            blocks, names = [block] + blocks, [name] + names
            states = [f"{name}{i + 1}" for i in range(block[0].shape[0])] + states
    a_d, b_d, c_d = dropped
    gain_d = -c_d @ np.linalg.solve(a_d, b_d) if a_d.shape[0] else np.zeros(plant.D.shape)
    d_r = plant.D + gain_d if keep_dc_gain else plant.D
    reduced = control.ss(*_join(blocks, plant), d_r, states=states,
                         inputs=plant.input_labels, outputs=plant.output_labels,
                         name=f"{plant.name}_modal{len(states)}")
    error = _hinf(a_d, b_d, c_d, -gain_d if keep_dc_gain else np.zeros(plant.D.shape))
    discarded_poles = np.linalg.eigvals(a_d) if a_d.shape[0] else np.zeros(0, dtype=complex)
    return Reduction(system=reduced, method=METHODS[1] if keep_dc_gain else METHODS[0],
                     error=error, error_bound=error, kept=tuple(names),
                     discarded=tuple(f"mode{j + 1}" for j in range(n_kept, len(pairs))),
                     discarded_poles=discarded_poles[np.argsort(np.abs(discarded_poles))])


def _mode_blocks(kept, pairs):
    """The kept modes one by one (a cluster of equal poles stays one block), lowest first."""
    blocks, names, states, rest, j = [], [], [], kept, 0
    while j < len(pairs):
        block, rest = _peel(*rest, _near(pairs[j:j + 1]))
        size = block[0].shape[0]
        if size == 2:
            blocks.append(_companion(*block))
            names.append(f"mode{j + 1}")
            states += [f"mode{j + 1}", f"mode{j + 1}_dot"]
        else:
            blocks.append(block)
            names.append(f"modes{j + 1}-{j + size // 2}")
            states += [f"mode{j + 1}_{i + 1}" for i in range(size)]
        j += size // 2
    return blocks, names, states


# ------------------------------------------------------------------ balanced truncation
def _factor(gramian):
    """``L`` with ``L L^T = gramian`` (symmetric, positive semidefinite to round-off)."""
    values, vectors = np.linalg.eigh((gramian + gramian.T) / 2.0)
    return vectors * np.sqrt(np.clip(values, 0.0, None))


def _balance(a, b, c, order):
    """Square-root balanced truncation of a stable ``(a, b, c)`` to ``order`` states:
    ``(a_r, b_r, c_r)`` and all Hankel singular values, decreasing."""
    controllability = scipy.linalg.solve_continuous_lyapunov(a, -b @ b.T)
    observability = scipy.linalg.solve_continuous_lyapunov(a.T, -c.T @ c)
    l_c, l_o = _factor(controllability), _factor(observability)
    u, hsv, vt = np.linalg.svd(l_o.T @ l_c)
    scale = 1.0 / np.sqrt(hsv[:order])
    right = l_c @ vt[:order].T * scale
    left = (u[:, :order] * scale).T @ l_o.T
    return (left @ a @ right, left @ b, c @ right), hsv


def _refuse_undamped(owner, poles):
    """An :class:`InputValueError` for flexible modes on the imaginary axis."""
    undamped = sorted({round(abs(p.imag), 12) for p in poles.all
                       if poles.marginal(p) and poles.oscillatory(p)})
    if undamped:
        shown = ", ".join(f"{w:.4g}" for w in undamped[:6]) + (", .." if len(undamped) > 6
                                                               else "")
        raise InputValueError(
            f"{owner}.model_or_sys must have damped flexible modes (balanced truncation is not "
            f"defined for poles on the imaginary axis: their Gramians are infinite); got "
            f"{len(undamped)} undamped (or unstable) modes at {shown} rad/s. Damp the beams "
            "(damping_ratio > 0, e.g. the scene key beam.damping_ratio) or use modal_truncation")


def _refuse_zero_hsv(owner, order, n_rigid, hsv):
    """An :class:`InputValueError` for an order that keeps a Hankel singular value of zero."""
    k = order - n_rigid
    if k and hsv[k - 1] <= HSV_FLOOR * hsv[0]:
        minimal = int(np.sum(hsv > HSV_FLOOR * hsv[0]))
        raise InputValueError(f"{owner}.order must be <= {n_rigid + minimal}: the stable part "
                              f"has {minimal} Hankel singular values above {HSV_FLOOR:g} of the "
                              f"largest (the others are uncontrollable or unobservable states); "
                              f"got {order}")


def balanced_truncation(model_or_sys, order, *, spin_rate=0.0) -> Reduction:
    """Square-root balanced truncation of the stable part, the rigid-body part kept whole.

    The poles on or right of the imaginary axis (the rigid-body modes: a hub's double
    integrator, a free hub's translation; any unstable pole of a general plant) are split off
    exactly and kept; the asymptotically stable rest ``G_s`` is balanced (its Gramians by
    :func:`scipy.linalg.solve_continuous_lyapunov`, the square-root method) and truncated to
    ``order - n_rigid`` states. Then ``sigma_{k+1} <= ||G - G_r||_inf <= 2 sum_{i>k} sigma_i``
    with ``sigma_i`` the Hankel singular values of ``G_s`` and ``k`` the balanced states kept.
    No slycot needed (``control.balred`` needs it and cuts at ``Re p = alpha`` instead).

    Parameters
    ----------
    model_or_sys : Model or control.StateSpace
        A flexctl model (linearised about ``spin_rate``) or a continuous-time plant. Its
        flexible modes must be damped (``beam.damping_ratio > 0``): an undamped mode sits on
        the imaginary axis, where the Gramians do not exist.
    order : int
        States of the reduced plant, from the rigid-body part's size to the plant's.
    spin_rate : float, optional
        Steady hub rate, rad/s, for a model (0 for a ``StateSpace``).

    Returns
    -------
    Reduction
        ``system`` with states ``rigid1..``, ``balanced1..``; ``error_bound`` the bound
        above, ``error`` the computed ``||G - G_r||_inf``, ``hankel_singular_values``.

    Raises
    ------
    InputValueError
        For an undamped flexible mode (use :func:`modal_truncation`, or damp the beam), an
        order below the rigid-body part or above the plant, or one that keeps a Hankel
        singular value of zero (uncontrollable or unobservable states: ask for fewer).

    Examples
    --------
    >>> from flexctl import build_model, load_scene
    >>> scene = load_scene("hub-beam-mass", {"beam.damping_ratio": 0.01})
    >>> reduced = balanced_truncation(build_model(scene.system, n_modes=4), 6)
    >>> reduced.system.state_labels
    ['rigid1', 'rigid2', 'balanced1', 'balanced2', 'balanced3', 'balanced4']
    >>> bool(reduced.hankel_singular_values[4] <= reduced.error <= reduced.error_bound)
    True
    """
    import control

    owner = "balanced_truncation"
    check_integer(owner, "order", order, minimum=1)
    plant = _plant(owner, model_or_sys, spin_rate)
    check_integer(owner, "order", order, minimum=1, maximum=plant.nstates)
    poles = _Poles(plant.A)
    _refuse_undamped(owner, poles)
    rigid, stable = _peel(plant.A, plant.B, plant.C, poles.marginal)
    n_rigid = rigid[0].shape[0]
    if order < n_rigid:
        raise InputValueError(f"{owner}.order must be >= {n_rigid}, the states of the "
                              f"rigid-body part (poles on or right of the imaginary axis, kept "
                              f"whole); got {order}")
    k = order - n_rigid
    (a_b, b_b, c_b), hsv = _balance(*stable, k) if stable[0].shape[0] else (stable, np.zeros(0))
    _refuse_zero_hsv(owner, order, n_rigid, hsv)
    states = [f"rigid{i + 1}" for i in range(n_rigid)] + [f"balanced{i + 1}" for i in range(k)]
    reduced = control.ss(*_join([rigid, (a_b, b_b, c_b)], plant), plant.D, states=states,
                         inputs=plant.input_labels, outputs=plant.output_labels,
                         name=f"{plant.name}_balanced{order}")
    a_s, b_s, c_s = stable
    error = _hinf(scipy.linalg.block_diag(a_s, a_b), np.vstack([b_s, b_b]),
                  np.hstack([c_s, -c_b]), np.zeros(plant.D.shape)) if k < len(hsv) else 0.0
    return Reduction(system=reduced, method=METHODS[2], error=error,
                     error_bound=2.0 * float(np.sum(hsv[k:])),
                     kept=(("rigid",) if n_rigid else ()) + tuple(states[n_rigid:]),
                     discarded=tuple(f"balanced{i + 1}" for i in range(k, len(hsv))),
                     hankel_singular_values=hsv)


# ------------------------------------------------------------------ the H_inf norm
def hinf_norm(system) -> float:
    """``||G||_inf = sup_w sigma_max(G(jw))`` of a continuous-time plant, without slycot.

    The Bruinsma-Steinbuch iteration: a lower bound from the frequency response at ``0``,
    infinity and the poles' frequencies, raised at the midpoints of the imaginary eigenvalues
    of the Hamiltonian matrix until it has none at ``(1 + 2 NORM_RTOL)`` times the bound,
    which is then returned (so the value is an upper bound, within :data:`NORM_RTOL`).
    ``control.norm(sys, "inf")`` does this with slycot; its SciPy fallback bisects with an
    absolute tolerance on the eigenvalues' real parts, too coarse for lightly damped beams.

    Parameters
    ----------
    system : control.StateSpace
        Continuous time.

    Returns
    -------
    float
        The norm, in the outputs' units per input unit; ``inf`` if a pole is on or right of
        the imaginary axis (to :data:`MARGINAL_DAMPING`).

    Examples
    --------
    >>> import control
    >>> round(hinf_norm(control.ss([[0, 1], [-4, -0.4]], [[0], [1]], [[1, 0]], 0)), 4)
    1.2563
    """
    plant = _plant("hinf_norm", system, 0.0, name="system")
    return _hinf(plant.A, plant.B, plant.C, plant.D)


def _hinf(a, b, c, d, rtol=NORM_RTOL, max_iterations=100) -> float:
    if a.shape[0] == 0 or not np.any(b) or not np.any(c):
        return float(np.linalg.norm(d, 2)) if d.size else 0.0
    poles = _Poles(a)
    if not poles.stable():
        return float("inf")
    eye = np.eye(a.shape[0])

    def gain(w):
        return np.linalg.norm(d + c @ np.linalg.solve(1j * w * eye - a, b), 2)

    candidates = np.concatenate([[0.0], np.abs(poles.all), np.abs(poles.all.imag)])
    lower = max([np.linalg.norm(d, 2)] + [gain(w) for w in candidates])
    if lower == 0.0:
        return 0.0
    for _ in range(max_iterations):
        gamma = (1.0 + 2.0 * rtol) * lower
        ev = np.linalg.eigvals(_hamiltonian(a, b, c, d, gamma))
        crossing = np.sort(np.abs(ev[np.abs(ev.real) <= 1e-6 * np.maximum(np.abs(ev), 1.0)]
                                  .imag))
        if crossing.size == 0:
            return float(gamma)
        points = np.concatenate([[0.0], crossing])
        new = max(gain(w) for w in (points[:-1] + points[1:]) / 2.0)
        if new <= lower:
            return float(gamma)
        lower = new
    return float((1.0 + 2.0 * rtol) * lower)


def _hamiltonian(a, b, c, d, gamma):
    """Its imaginary eigenvalues ``jw`` are where ``gamma`` is a singular value of ``G(jw)``."""
    r = gamma ** 2 * np.eye(d.shape[1]) - d.T @ d
    r_inv_bt = np.linalg.solve(r, b.T)
    r_inv_dt = np.linalg.solve(r, d.T)
    a_h = a + b @ r_inv_dt @ c
    return np.block([[a_h, b @ r_inv_bt],
                     [-c.T @ (np.eye(d.shape[0]) + d @ r_inv_dt) @ c, -a_h.T]])
