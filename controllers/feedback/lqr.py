"""Linear-quadratic regulator on a truncated linear plant, with Bryson-style physical weights.

:func:`design_lqr` linearises a model about a steady spin, turns :class:`LQRWeights` (largest
acceptable hub angle error, hub rate, tip deflection, flexible-mode energy and torque) into
``Q`` and ``R`` (:func:`lqr_weight_matrices`) and solves the Riccati equation with
:func:`control.lqr`. The design model usually has fewer modes than the plant it runs on: the
:class:`LQR` controller reads the design model's states out of the plant's larger state
(:func:`truncate_state`), so the higher modes are neither fed back nor estimated (spillover).

Notes
-----
With ``N`` plant modes and ``M <= N`` design modes, the plant state is
``x = [theta, q_1..q_N, theta_dot, q_1_dot..q_N_dot]`` (``2 N + 2``) and the design state is
``x_d = [theta, q_1..q_M, theta_dot, q_1_dot..q_M_dot]`` (``2 M + 2``), ``x_d = P x`` with
``P = truncation_matrix(N, M)``. Both orders are the design model's
:class:`~flexctl.model.layout.StateLayout` (``model.layout``) on ``M`` and ``N`` modes: the
design state is the plant's ``plant_layout.projection(design_layout)``
(:mod:`controllers.design.plant_state`). A reference slew sets
``x_ref = [theta_ref, 0..0, rate_ref, 0..0]`` and the torque is
``u = -K (x_d - x_ref) + J0 acc_ref`` (the feedforward optional), clipped to the torque limit.

Spillover: the modes left out of the design are undamped unless the beam has modal damping.
To first order a static gain moves the real part of left-out mode ``k`` (mass-normalised
hub-free mode shape ``phi_k``, hub entry ``phi_k0``) by
``-1/2 phi_k0 (k_theta_dot phi_k0 + sum_i k_q_dot_i phi_ki)``: the hub-rate gain always
damps, the flexible-rate gains may not. Weight the hub rate strongly (small ``hub_rate``)
to keep the hub-rate gain dominant, and check with :func:`closed_loop_poles` on a plant
with more modes.

Examples
--------
>>> import flexctl
>>> from controllers.feedback.lqr import LQRWeights, design_lqr
>>> model = flexctl.build_model(flexctl.load_scene("hub-beam-mass").system, n_modes=2)
>>> lqr = design_lqr(model, LQRWeights(hub_angle=0.05, torque=5.0, tip_deflection=0.05))
>>> lqr.gain.shape, bool(lqr.poles.real.max() < 0)
((1, 6), True)
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from flexctl.model import Model
from flexctl.model.checks import (KeywordOnly, check_array, check_instance, check_integer,
                                  check_real)
from flexctl.model.errors import InputTypeError, InputValueError
from flexctl.model.layout import StateLayout

from ..design.controllable import design_failure, lqr_on_part
from .reference_feedback import ReferenceFeedback
from ..design.plant_state import DEFAULT_LAYOUT, design_rows, resized
from ..spec import WEIGHT_RANGE
from ..slew.reference import (casadi_evaluate, evaluate_reference, optional_positive,
                              reference_parameters)

__all__ = ["LQRWeights", "LQR", "design_lqr", "lqr_weight_matrices", "truncation_matrix",
           "truncate_state", "reference_state", "closed_loop_poles", "static_deflection_gain"]


def checked_model(owner: str, model) -> Model:
    """``model`` itself when it is a flexctl :class:`~flexctl.Model`.

    Parameters
    ----------
    owner : str
        The function named in the error message.
    model : object
        The object to check.

    Raises
    ------
    InputTypeError
        If ``model`` is not a flexctl Model.
    """
    return check_instance(owner, "model", model, Model, "flexctl Model")


def _n_modes(owner: str, name: str, value, minimum: int = 1) -> int:
    return check_integer(owner, name, value, minimum=minimum)


def _layout(owner: str, design) -> StateLayout:
    """The design state's layout: ``design`` itself, or one appendage of ``design`` modes on a
    pinned hub."""
    if isinstance(design, StateLayout):
        return design
    return StateLayout.single(_n_modes(owner, "n_design_modes", design))


def gain_layout(owner: str, layout, n_states: int) -> StateLayout:
    """The layout of a design state of ``n_states`` entries (a gain's width): ``layout``
    checked against it, or one appendage on a pinned hub (a gain given without a model).

    Parameters
    ----------
    owner : str
        The law named in the error messages.
    layout : StateLayout or None
        The design model's ``model.layout``, or None for one appendage on a pinned hub.
    n_states : int
        Length of the design state (the gain's number of columns).

    Raises
    ------
    InputTypeError
        If ``layout`` is neither None nor a StateLayout.
    InputValueError
        If ``layout`` has another number of states, or no one-appendage layout has
        ``n_states``.
    """
    if layout is None:
        layout = resized(DEFAULT_LAYOUT, n_states)
        if layout is None:
            raise InputValueError(f"{owner}.gain must be finite with shape (1, 2 M + 2), M >= 1;"
                                  f" got {n_states} columns")
    if not isinstance(layout, StateLayout):
        raise InputTypeError(f"{owner}.layout must be a StateLayout (the design model's "
                             f"model.layout); got {type(layout).__name__}")
    if layout.n_states != n_states:
        raise InputValueError(f"{owner}.layout has {layout.n_states} states but the gain "
                              f"{n_states} columns")
    return layout


def truncation_matrix(n_plant_modes, n_design_modes) -> np.ndarray:
    """``P`` with ``x_design = P x_plant`` (module Notes), shape (2 M + 2, 2 N + 2).

    Parameters
    ----------
    n_plant_modes : int or StateLayout
        ``N``, or the plant state's layout.
    n_design_modes : int or StateLayout
        ``M``, or the design state's layout (``model.layout`` of the design model).

    Raises
    ------
    ValueError
        If ``n_design_modes > n_plant_modes``.
    """
    design = _layout("truncation_matrix", n_design_modes)
    plant = n_plant_modes if isinstance(n_plant_modes, StateLayout) else design.with_modes(
        _n_modes("truncation_matrix", "n_plant_modes", n_plant_modes))
    if design.n_modes > plant.n_modes:
        raise InputValueError(f"truncation_matrix.n_design_modes must be <= n_plant_modes = "
                              f"{plant.n_modes} (the plant must have at least the design's "
                              f"modes); got {design.n_modes}")
    return np.eye(plant.n_states)[plant.projection(design)]


def truncate_state(x, n_design_modes) -> np.ndarray:
    """Design-model state ``[theta, q_1..q_M, theta_dot, q_1_dot..q_M_dot]`` of a plant state.

    Parameters
    ----------
    x : array_like, shape (2 N + 2,)
        Plant state with ``N >= M`` modes.
    n_design_modes : int or StateLayout
        ``M``, or the design state's layout (``model.layout`` of the design model).

    Returns
    -------
    ndarray, shape (2 M + 2,)
    """
    x = check_array("truncate_state", "x", x, finite=False)
    design = _layout("truncate_state", n_design_modes)
    if x.ndim != 1:
        raise InputValueError("truncate_state.x must be a plant state vector of even length; "
                              f"got shape {x.shape}")
    return x[design_rows(design, x.size)]


#: Time step of the central difference that gives the reference jerk, s.
_JERK_STEP = 1e-5


def static_deflection_gain(model) -> np.ndarray:
    """``K_ff^-1 m_tf``: the beam's quasi-static modal deflection per unit hub acceleration.

    Under a slow hub acceleration ``theta_tt`` the beam equation ``M_ff q_tt + K_ff q =
    -m_tf theta_tt`` leaves ``q = -K_ff^-1 m_tf theta_tt``, m per rad/s^2, shape (M,).

    Parameters
    ----------
    model : flexctl.Model
        The design model (``M`` modes).
    """
    return checked_model("static_deflection_gain", model).quasi_static_gain()


def reference_state(reference, t: float, n_modes, deflection_gain=None) -> tuple:
    """Reference design state (shape (2 M + 2,)) and hub acceleration ``acc_ref`` at ``t``.

    ``x_ref = [theta_ref, q_ref, rate_ref, q_dot_ref]`` with ``q_ref = 0`` (rigid reference,
    ``deflection_gain=None``) or the quasi-static deflection ``q_ref = -g acc_ref`` and
    ``q_dot_ref = -g jerk_ref`` (``g`` from :func:`static_deflection_gain`): a beam that bends
    as much as the commanded acceleration needs, instead of one held straight against it.

    Parameters
    ----------
    reference : object or None
        Hub reference with ``angle(t)``, ``rate(t)``, ``acceleration(t)`` (rad, rad/s,
        rad/s^2), e.g. a :class:`~controllers.slew.reference.SlewProfile`; None: rest at 0.
    t : float
        Time, s.
    n_modes : int or StateLayout
        ``M``, or the design state's layout (``model.layout`` of the design model).
    deflection_gain : array_like, shape (M,), optional
        ``g``, m per rad/s^2. Default: a rigid reference (``q_ref = 0``).
    """
    layout = _layout("reference_state", n_modes)
    angle, rate, acc = evaluate_reference(reference, t)
    x_ref = layout.zeros()
    x_ref[layout.theta], x_ref[layout.theta_dot] = angle, rate
    if deflection_gain is not None and reference is not None:
        jerk = (evaluate_reference(reference, t + _JERK_STEP)[2]
                - evaluate_reference(reference, t - _JERK_STEP)[2]) / (2.0 * _JERK_STEP)
        x_ref[layout.q] = -deflection_gain * acc
        x_ref[layout.q_dot] = -deflection_gain * jerk
    return x_ref, acc


def casadi_truncate_state(x, n_design_modes):
    """:func:`truncate_state` of a CasADi plant state vector.

    Parameters
    ----------
    x : CasADi column, shape (2 N + 2, 1)
        Plant state with ``N >= M`` modes.
    n_design_modes : int or StateLayout
        ``M``, or the design state's layout (``model.layout`` of the design model).
    """
    design = _layout("truncate_state", n_design_modes)
    return x[design_rows(design, x.numel()).tolist()]


def casadi_reference_state(reference, t, n_modes, deflection_gain=None,
                           reference_numbers=None) -> tuple:
    """:func:`reference_state` on the CasADi symbol ``t``: ``(x_ref (2 M + 2, 1), acc_ref)``;
    the reference's numbers are the symbols ``reference_numbers`` where given.

    Parameters
    ----------
    reference : object or None
        Hub reference with a ``casadi_reference`` method (e.g. a
        :class:`~controllers.slew.reference.SlewProfile`); None: rest at 0.
    t : CasADi scalar
        Time, s.
    n_modes : int or StateLayout
        ``M``, or the design state's layout.
    deflection_gain : array_like or CasADi column, shape (M,), optional
        ``g``, m per rad/s^2 (numbers, or parameter symbols). Default: a rigid reference.
    reference_numbers : CasADi column, optional
        The reference's numbers as symbols, laid out as
        :func:`~controllers.slew.reference.reference_parameters`. Default: its own numbers.
    """
    import casadi as ca

    layout = _layout("reference_state", n_modes)
    angle, rate, acc = casadi_evaluate(reference, t, reference_numbers)
    q_ref = q_dot_ref = ca.DM.zeros(layout.n_modes)
    if deflection_gain is not None and reference is not None:
        jerk = (casadi_evaluate(reference, t + _JERK_STEP, reference_numbers)[2]
                - casadi_evaluate(reference, t - _JERK_STEP, reference_numbers)[2]) \
            / (2.0 * _JERK_STEP)
        gain = (deflection_gain if isinstance(deflection_gain, (ca.SX, ca.MX))
                else ca.DM(np.asarray(deflection_gain, dtype=float)))
        q_ref, q_dot_ref = -gain * acc, -gain * jerk
    return layout.join(theta=angle, q=q_ref, theta_dot=rate, q_dot=q_dot_ref), acc


#: Bryson values of :class:`LQRWeights` must lie within [1 / WEIGHT_RANGE, WEIGHT_RANGE]
#: (owned by :mod:`controllers.spec`, which the scene parser reads).


@dataclass(frozen=True, kw_only=True)
class LQRWeights(KeywordOnly):
    """Largest acceptable values (Bryson's rule) that weight the LQR cost.

    Each term adds ``(value / largest)^2`` to the cost integrand; ``None`` leaves it out.

    Parameters
    ----------
    hub_angle : float
        Hub angle error, rad (> 0).
    torque : float
        Hub torque, N m (> 0).
    hub_rate : float, optional
        Hub rate error, rad/s (> 0).
    tip_deflection : float, optional
        Tip deflection, m (> 0); weighted through its output-matrix row.
    modal_energy : float, optional
        Elastic plus relative kinetic energy of the beam,
        ``E = 1/2 q^T K_ff q + 1/2 q_dot^T M_ff q_dot``, J (> 0); the cost adds
        ``E / modal_energy``.
    """

    hub_angle: float
    torque: float
    hub_rate: float | None = None
    tip_deflection: float | None = None
    modal_energy: float | None = None

    def __post_init__(self):
        for name in ("hub_angle", "torque"):
            object.__setattr__(self, name, check_real("lqr_weights", name, getattr(self, name),
                                                 minimum=0.0, strict=True))
        for name in ("hub_rate", "tip_deflection", "modal_energy"):
            object.__setattr__(self, name,
                               optional_positive("lqr_weights", name, getattr(self, name)))
        for name in ("hub_angle", "torque", "hub_rate", "tip_deflection", "modal_energy"):
            value = getattr(self, name)
            # the cost squares their inverses: 1e-200 overflows, and weights this far apart
            # leave the Riccati equation nothing but rounding error
            if value is not None and not 1.0 / WEIGHT_RANGE <= value <= WEIGHT_RANGE:
                raise InputValueError(f"lqr_weights.{name} must lie in [{1.0 / WEIGHT_RANGE:g}, "
                                      f"{WEIGHT_RANGE:g}]; got {value!r}")


def lqr_weight_matrices(model, weights: LQRWeights) -> tuple:
    """``Q`` (shape (n, n)) and ``R`` (shape (1, 1)) of :class:`LQRWeights` on ``model``.

    ``x^T Q x = (theta/hub_angle)^2 + (theta_dot/hub_rate)^2 + (tip/tip_deflection)^2
    + E(q, q_dot)/modal_energy`` and ``R = 1/torque^2``, with states in the model's order.

    Parameters
    ----------
    model : flexctl.Model
        The design model (its layout, output matrix and modal matrices).
    weights : LQRWeights
        Largest acceptable values of each term.
    """
    model = checked_model("lqr_weight_matrices", model)
    if not isinstance(weights, LQRWeights):
        raise InputTypeError(f"lqr_weight_matrices.weights must be LQRWeights; got "
                             f"{type(weights).__name__}")
    layout = model.layout
    q_mat = np.zeros((layout.n_states, layout.n_states))
    q_mat[layout.theta, layout.theta] = weights.hub_angle ** -2
    if weights.hub_rate is not None:
        q_mat[layout.theta_dot, layout.theta_dot] += weights.hub_rate ** -2
    if weights.tip_deflection is not None:
        for k, name in enumerate(model.output_names):
            if name.endswith("tip_deflection"):        # every appendage's tip
                row = model.output_matrix[k]
                q_mat += np.outer(row, row) / weights.tip_deflection ** 2
    if weights.modal_energy is not None:
        mat = model.matrices
        q_mat[layout.q, layout.q] += mat.K_ff / (2.0 * weights.modal_energy)
        q_mat[layout.q_dot, layout.q_dot] += mat.M_ff / (2.0 * weights.modal_energy)
    return 0.5 * (q_mat + q_mat.T), np.array([[weights.torque ** -2]])


@dataclass(frozen=True, kw_only=True, eq=False)
class LQR(ReferenceFeedback):
    """State feedback ``u = -K (x_d - x_ref) + J acc_ref`` (a :class:`flexctl.Controller`).

    Build with :func:`design_lqr`. See the module Notes for the state orders.

    Parameters
    ----------
    reference : object, optional
        Hub reference with ``angle``, ``rate``, ``acceleration`` (e.g. a
        :class:`~controllers.slew.reference.SlewProfile`). Default: regulate to 0.
    feedforward_inertia : float, optional
        ``J`` of the feedforward term, kg m^2 (> 0). Default none.
    torque_limit : float, optional
        Saturation, N m (> 0). Default none.
    plant_layout : StateLayout, optional
        The plant state's layout, set by :meth:`for_plant` (:func:`flexctl.simulate` binds
        every law to its plant). Default None: a bare state read with the design's blocks.
    gain : array_like, shape (1, 2 M + 2)
        ``K`` on the design state, N m per state unit.
    spin_rate : float, optional
        Spin rate of the design linearisation, rad/s (for the record).
    poles : ndarray, optional
        Closed-loop poles of the design model, 1/s (for the record).
    deflection_gain : ndarray, shape (M,), optional
        Track the quasi-static beam deflection of the reference (:func:`reference_state`);
        default a rigid reference.
    layout : StateLayout, optional
        The design state's layout (the design model's ``model.layout``); default one
        appendage of ``M`` modes on a pinned hub.
    """

    gain: np.ndarray
    spin_rate: float = 0.0
    poles: np.ndarray = field(default=None, repr=False)
    deflection_gain: np.ndarray | None = field(default=None, repr=False)
    layout: StateLayout | None = field(default=None, repr=False)

    owner = "lqr"

    def __post_init__(self):
        gain = check_array("lqr", "gain", self.gain, finite=False).copy()
        if gain.ndim == 1:
            gain = gain[None, :]
        if gain.ndim != 2 or gain.shape[0] != 1 or gain.shape[1] < 2 or gain.shape[1] % 2 \
                or not np.all(np.isfinite(gain)):
            raise InputValueError("lqr.gain must be finite with shape (1, 2 M + 2); got "
                                  f"shape {gain.shape}")
        gain.setflags(write=False)
        object.__setattr__(self, "gain", gain)
        object.__setattr__(self, "layout", gain_layout("lqr", self.layout, gain.shape[1]))
        object.__setattr__(self, "spin_rate", check_real("lqr", "spin_rate", self.spin_rate))
        super().__post_init__()

    @property
    def n_modes(self) -> int:
        """Number of design modes ``M``."""
        return self.layout.n_modes

    def state_gain(self, n_modes) -> np.ndarray:
        """``K P``: the gain on a plant state with ``n_modes >= M`` modes (or of that
        layout), shape (1, 2N+2).

        Parameters
        ----------
        n_modes : int or StateLayout
            ``N >= M``, the plant's modes, or the plant state's layout.
        """
        return self.gain @ truncation_matrix(n_modes, self.layout)

    def plant_gain(self, plant, spin_rate: float = 0.0) -> np.ndarray:
        """``K P`` on ``plant``'s state (any spin rate: the gain is fixed), shape (1, n).

        Parameters
        ----------
        plant : flexctl.Model
            The plant, with at least the design's modes in each appendage.
        spin_rate : float, optional
            Steady hub rate, rad/s (not read). Default 0.
        """
        return self.state_gain(plant.layout)

    def torque(self, t: float, x, z=None) -> float:
        """Hub torque, N m.

        Parameters
        ----------
        t : float
            Time, s.
        x : array_like, shape (n,)
            Plant state (``2 N + 2`` for one beam of ``N >= M`` modes), in the order of the
            plant's layout.
        z : array_like, shape (0,), optional
            Internal state (none; not read).
        """
        x_design = self._design_state(x)
        x_ref, acc = reference_state(self.reference, t, self.layout, self.deflection_gain)
        return self._apply(-float(self.gain[0] @ (x_design - x_ref)), acc)


    @property
    def casadi_parameters(self) -> tuple:
        """``(structure, values)``: what shapes :meth:`casadi_torque` (design state
        layout, reference, which options are on) and its numbers ``[K, feedforward_inertia,
        torque_limit, deflection_gain, reference numbers]`` (0 for an option that is off, no
        deflection gain for a rigid reference). Compiled runs of LQR laws of one structure (a
        slew of any angle and duration included) share their integrators."""
        reference, numbers = reference_parameters(self.reference)
        structure = (self.layout, reference,
                     self.feedforward_inertia is None, self.torque_limit is None,
                     self.deflection_gain is None)
        extra = () if self.deflection_gain is None else self.deflection_gain
        return structure, np.concatenate((self.gain[0], [self.feedforward_inertia or 0.0,
                                                         self.torque_limit or 0.0], extra,
                                          numbers))

    def casadi_torque(self, t, x, parameters=None):
        """:meth:`torque` as a CasADi expression of the symbols ``t`` and ``x``; the numbers
        are symbols too when ``parameters`` is given.

        Parameters
        ----------
        t : CasADi scalar
            Time, s.
        x : CasADi column, shape (n, 1)
            Plant state, in the order of the plant's layout.
        parameters : CasADi column, optional
            Symbols laid out as the values of :attr:`casadi_parameters`. Default: this
            law's numbers.
        """
        import casadi as ca

        gain, inertia, limit = ca.DM(self.gain[0]), None, None
        deflection, numbers = self.deflection_gain, None
        if parameters is not None:
            # the numbers in casadi_parameters' order: gain row, inertia, limit, deflection,
            # reference
            m = self.gain.shape[1]
            d = 0 if deflection is None else np.size(deflection)
            # sizes: the gain row, the inertia, the limit, the deflection gain; the rest
            offsets = np.cumsum([0, m, 1, 1, d]).tolist() + [parameters.numel()]
            gain, inertia, limit, rest, numbers = ca.vertsplit(parameters, offsets)
            deflection = None if deflection is None else rest
        x_design = self._casadi_design_state(x)
        x_ref, acc = casadi_reference_state(self.reference, t, self.layout, deflection,
                                            numbers)
        return self._casadi_apply(-ca.dot(gain, x_design - x_ref), acc, inertia, limit)


def lqr_gain(model, weights, spin_rate, sample_time=None):
    """Gain and closed-loop poles on the modes the torque moves
    (:mod:`controllers.design.controllable`:
    all of them for one beam, where this is ``control.lqr`` of the linearisation).

    Parameters
    ----------
    model : flexctl.Model
        The design model.
    weights : LQRWeights
        Largest acceptable values (:func:`lqr_weight_matrices`).
    spin_rate : float
        Steady hub rate of the linearisation, rad/s.
    sample_time : float, optional
        Hold of a sampled law, s: the discrete LQR of the plant held over it. Default: the
        continuous LQR.

    Returns
    -------
    gain : ndarray, shape (1, n)
        ``K``, ``u = -K x``.
    poles : ndarray, shape (n,)
        ``eig(A - B K)`` of the continuous linearisation, 1/s.
    """
    q_mat, r_mat = lqr_weight_matrices(model, weights)
    gain, poles, _ = lqr_on_part(model, spin_rate, q_mat, r_mat, sample_time)
    return gain, poles


def checked_on(controller, plant):
    """:func:`controllers.design.stability.checked_on` (imported when called: it imports this).

    Parameters
    ----------
    controller : object
        The designed law (or the law behind a hold).
    plant : flexctl.Model or None
        The plant the law will run on; None skips the check.
    """
    from ..design.stability import checked_on as check

    return check(controller, plant, stacklevel=3)


def design_lqr(model, weights: LQRWeights, spin_rate: float = 0.0, *, reference=None,
               feedforward: bool = True, torque_limit: float | None = None,
               flexible_reference: bool = True, sample_time: float | None = None,
               plant=None) -> LQR:
    """LQR on ``model.linearize(spin_rate)`` with the weights of :func:`lqr_weight_matrices`.

    Parameters
    ----------
    model : flexctl.Model
        Design model (``M`` modes); the plant it later runs on may have more.
    weights : LQRWeights
        Largest acceptable values of each term of the cost.
    spin_rate : float, optional
        Steady hub rate of the linearisation, rad/s. Default 0.
    reference : object, optional
        Hub reference (see :class:`LQR`).
    feedforward : bool, optional
        Add ``J0 acc_ref`` with the model's rigid inertia ``J0``. Default True.
    torque_limit : float, optional
        Saturation, N m.
    flexible_reference : bool, optional
        Track the quasi-static deflection the reference acceleration needs
        (:func:`reference_state`) rather than a straight beam. Default True.
    sample_time : float, optional
        For a law run with a zero-order hold (s): the discrete LQR of the plant held over
        it (:func:`controllers.design.controllable.state_gain`), stable where the continuous gain
        held that long is not. Default: the continuous LQR.
    plant : flexctl.Model, optional
        The plant the law will run on (its own modes and variant): the loop is checked on
        its linearisation (:func:`controllers.design.stability.check_loop`) and an unstable or
        nearly unstable loop warns (:class:`~controllers.design.stability.LoopStabilityWarning`).

    Returns
    -------
    LQR
        ``gain`` equals ``control.lqr(model.linearize(spin_rate), Q, R)[0]`` when the torque
        moves every mode; otherwise the LQR gain of the modes it moves, zero on the others
        (symmetric appendages bending against each other, a free hub's translation;
        :mod:`controllers.design.controllable`).
    """
    model = checked_model("design_lqr", model)
    spin_rate = check_real("design_lqr", "spin_rate", spin_rate)
    if sample_time is not None:
        sample_time = check_real("design_lqr", "sample_time", sample_time, minimum=0.0, strict=True)
    with design_failure("lqr", "design_lqr", model, spin_rate, weights=weights,
                        sample_time=sample_time):
        gain, poles = lqr_gain(model, weights, spin_rate, sample_time)
    law = LQR(gain=gain, reference=reference,
              feedforward_inertia=float(model.rigid_inertia) if feedforward else None,
              torque_limit=torque_limit, spin_rate=spin_rate, poles=poles,
              deflection_gain=static_deflection_gain(model) if flexible_reference else None,
              layout=model.layout)
    if plant is not None and sample_time is not None:
        from flexctl.sim.digital import ZeroOrderHold

        checked_on(ZeroOrderHold(law, sample_time), plant)
        return law
    return checked_on(law, plant)


def closed_loop_poles(model, gain, spin_rate: float = 0.0) -> np.ndarray:
    """Poles of ``model.linearize(spin_rate)`` under the state feedback ``u = -gain x``.

    Parameters
    ----------
    model : flexctl.Model
        Plant with ``N`` modes.
    gain : array_like, shape (1, 2 N + 2)
        E.g. ``controller.state_gain(N)`` of a controller designed on fewer modes: the
        spillover check.
    spin_rate : float, optional
        Steady hub rate of the plant's linearisation, rad/s. Default 0.

    Returns
    -------
    ndarray, shape (2 N + 2,)
        1/s.
    """
    model = checked_model("closed_loop_poles", model)
    a, b = model.linear_matrices(spin_rate)
    gain = check_array("closed_loop_poles", "gain", gain).reshape(1, -1)
    if gain.shape[1] != model.n_states:
        raise InputValueError(f"closed_loop_poles.gain must have shape (1, {model.n_states}) for "
                              f"{model.n_modes} plant modes; got {gain.shape}")
    return np.linalg.eigvals(a - b @ gain)
