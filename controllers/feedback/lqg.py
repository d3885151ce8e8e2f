"""LQG: LQR on the state estimated by a Kalman filter from hub angle and root bending moment.

Only two signals are measured: the hub angle (an encoder) and the root bending moment of the
beam (a strain gauge). A steady-state Kalman filter (:func:`control.lqe`) estimates the state
from them; the torque is the LQR law of :mod:`controllers.feedback.lqr` (designed on the design
model)
applied to the estimate. The filter runs as the controller's internal state ``z`` inside
:func:`flexctl.simulate`, driven by the plant's measured outputs (the plant usually has more
modes than the design model: build the controller for it with :meth:`LQG.for_plant`).
:func:`design_lqg` given the plant builds the filter on the plant's modes (the design
model's variant), so that the modes the regulator leaves alone are estimated rather than fed
back through the innovation.

Notes
-----
Filter model with ``M`` modes (the design model's, or the plant's with
``estimate_plant_modes``), ``n_d = 2 M + 2`` states; plant with ``N >= M`` modes::

    z = x_hat = [theta, q_1..q_M, theta_dot, q_1_dot..q_M_dot]   (filter state order)
    y = [theta, root_moment] = C_meas x + v(t)                  (rad, N m)
    u = sat(-K (z - x_ref(t)) + J0 acc_ref(t))                  (N m)
    dz/dt = A z + B u + L (y - C z)

``A``, ``B``, ``C`` are the design model's, ``C_meas`` the plant's rows for ``theta`` and
``root_moment``. The filter assumes a white disturbance torque of intensity ``torque^2``
(N^2 m^2 s) entering like the control torque and white measurement noise of intensities
``angle^2`` (rad^2 s) and ``root_moment^2`` (N^2 m^2 s).

With an undamped beam (``damping_ratio = 0``) the root moment carries the unmodelled modes
too, and a filter that leaves them out feeds them back through its innovation, which may
destabilise them (observation spillover: slew-90's third mode grows at 0.024 1/s with a
filter of the design's 2 modes). Check with :meth:`LQG.closed_loop_poles` or
:func:`controllers.design.stability.check_loop`.
"""

from __future__ import annotations

from dataclasses import dataclass, field, replace

import numpy as np

from flexctl.model.checks import KeywordOnly, check_array, check_real
from flexctl.model.errors import InputTypeError, InputValueError
from flexctl.model.layout import StateLayout

from .reference_feedback import ReferenceFeedback
from ..design.controllable import design_failure, lqe_on_part
from .lqr import (LQRWeights, gain_layout, lqr_gain, checked_model, casadi_reference_state,
                  checked_on, reference_state, static_deflection_gain, truncation_matrix)
from ..design.plant_state import mode_count
from ..slew.reference import has_casadi

__all__ = ["NoiseLevels", "LQG", "design_lqg", "estimator_gain", "SumOfSines",
           "MEASURED_OUTPUTS", "measured_outputs"]

MEASURED_OUTPUTS = ("theta", "root_moment")


def measured_outputs(model) -> tuple:
    """The outputs the filter reads: ``theta`` and each appendage's root moment.

    Parameters
    ----------
    model : flexctl.Model
        The filter's model or the plant; its :attr:`~flexctl.Model.output_names` are read.
    """
    return ("theta",) + tuple(n for n in model.output_names if n.endswith("root_moment"))


def measurement_rows(model) -> np.ndarray:
    """The rows of ``model``'s output matrix that the filter's sensors read
    (:func:`measured_outputs`): ``y_meas = C_meas x``.

    Parameters
    ----------
    model : flexctl.Model
        The filter's model or the plant.

    Returns
    -------
    ndarray, shape (1 + K, n)
        Hub angle (rad) and each of the K appendages' root moments (N m) per state.
    """
    rows = [model.output_names.index(name) for name in measured_outputs(model)]
    return np.array(model.output_matrix[rows], dtype=float)


def _measurement_covariance(noise, model) -> np.ndarray:
    """``RN``: ``angle^2`` for theta, ``root_moment^2`` for each appendage's root moment."""
    roots = len(measured_outputs(model)) - 1
    return np.diag([noise.angle ** 2] + [noise.root_moment ** 2] * roots)


#: Bounds of a noise level (any unit): its square and its inverse square stay far inside the
#: floating-point range of the Kalman filter's Riccati equation.
MIN_NOISE, MAX_NOISE = 1e-100, 1e100


@dataclass(frozen=True, kw_only=True)
class NoiseLevels(KeywordOnly):
    """Noise intensities the Kalman filter is designed for, as standard deviations.

    Parameters
    ----------
    angle : float
        Hub angle measurement noise, rad (1e-100 to 1e100).
    root_moment : float
        Root bending moment measurement noise, N m (1e-100 to 1e100).
    torque : float
        Process noise: disturbance torque on the hub, N m (1e-100 to 1e100).
    """

    angle: float
    root_moment: float
    torque: float

    def __post_init__(self):
        # their squares are the Riccati equation's covariances: both must stay finite
        for name in ("angle", "root_moment", "torque"):
            object.__setattr__(self, name, check_real("noise", name, getattr(self, name),
                                                 minimum=MIN_NOISE, maximum=MAX_NOISE))

    @classmethod
    def from_sensors(cls, sensors, sample_time: float, torque: float = 0.1) -> "NoiseLevels":
        """The continuous-time intensities equivalent to ``sensors`` read every
        ``sample_time`` s: a reading of variance ``sigma^2`` per sample is white noise of
        intensity ``sigma^2 T`` (the encoder's ``sigma^2 = step^2 / 12``). A noiseless reading
        takes the floor of :data:`flexctl.sim.sensors.VARIANCE_FLOOR`.

        Parameters
        ----------
        sensors : flexctl.sim.sensors.Sensors
            The sensors: the encoder's resolution (rad) and the root moment's noise (N m,
            standard deviation per reading).
        sample_time : float
            Time between readings ``T``, s (> 0).
        torque : float, optional
            Process noise: disturbance torque on the hub, N m, as :attr:`torque`. Default 0.1.

        Examples
        --------
        >>> from flexctl.sim.sensors import Sensors
        >>> noise = NoiseLevels.from_sensors(Sensors(encoder_resolution=1.2e-3,
        ...                                          root_moment_noise=0.1), 0.01)
        >>> round(noise.angle, 6), round(noise.root_moment, 4)
        (3.5e-05, 0.01)
        """
        from flexctl.sim.sensors import VARIANCE_FLOOR, Sensors

        if not isinstance(sensors, Sensors):
            raise InputTypeError("noise.sensors must be a flexctl.sim.sensors.Sensors; got "
                                 f"{type(sensors).__name__}")
        period = check_real("noise", "sample_time", sample_time, minimum=0.0, strict=True)
        angle = max(sensors.attitude_variance, VARIANCE_FLOOR)
        moment = max((sensors.root_moment_noise or 0.0) ** 2, VARIANCE_FLOOR)
        return cls(angle=float(np.sqrt(angle * period)),
                   root_moment=float(np.sqrt(moment * period)), torque=torque)

    @property
    def measurement_covariance(self) -> np.ndarray:
        """``RN = diag(angle^2, root_moment^2)``, shape (2, 2)."""
        return np.diag([self.angle ** 2, self.root_moment ** 2])

    @property
    def process_covariance(self) -> np.ndarray:
        """``QN = [[torque^2]]``, shape (1, 1)."""
        return np.array([[self.torque ** 2]])


def estimator_gain(model, noise: NoiseLevels, spin_rate: float = 0.0) -> tuple:
    """Steady-state Kalman gain of ``model.linearize(spin_rate)`` measuring theta and root moment.

    Parameters
    ----------
    model : flexctl.Model
        The filter's model (``M`` modes).
    noise : NoiseLevels
        Noise the filter is designed for.
    spin_rate : float, optional
        Steady hub rate of the linearisation, rad/s. Default 0.

    Returns
    -------
    gain : ndarray, shape (2 M + 2, 2)
        ``L``, from ``control.lqe(A, B, C_meas, QN, RN)``.
    poles : ndarray, shape (2 M + 2,)
        Estimator poles ``eig(A - L C_meas)``, 1/s.
    """
    model = checked_model("estimator_gain", model)
    if not isinstance(noise, NoiseLevels):
        raise InputTypeError(f"estimator_gain.noise must be NoiseLevels; got "
                             f"{type(noise).__name__}")
    spin_rate = check_real("estimator_gain", "spin_rate", spin_rate)
    with design_failure("lqg", "estimator_gain", model, spin_rate, noise=noise,
                        solving="the Kalman filter Riccati equation"):
        return lqe_on_part(model, spin_rate, measurement_rows(model),
                           noise.process_covariance, _measurement_covariance(noise, model))


@dataclass(frozen=True, kw_only=True, eq=False)
class SumOfSines:
    """Deterministic band-limited noise: per channel a sum of sines with fixed random phases.

    Evaluates exactly at any ``t`` (the integrator may call it at any time, in any order), so a
    simulation with it is reproducible. Build with :meth:`from_levels`.

    Parameters
    ----------
    amplitudes : array_like, shape (C, K)
        Amplitude of each of the K sines of each of the C channels, in the channel's unit
        (e.g. rad, N m).
    frequencies : array_like, shape (C, K)
        Their frequencies, rad/s.
    phases : array_like, shape (C, K)
        Their phases at ``t = 0``, rad.
    """

    amplitudes: np.ndarray
    frequencies: np.ndarray
    phases: np.ndarray

    def __post_init__(self):
        arrays = [np.array(check_array("sum_of_sines", n, getattr(self, n), finite=False), ndmin=2)
                  for n in ("amplitudes", "frequencies", "phases")]
        if len({a.shape for a in arrays}) != 1 or not all(np.all(np.isfinite(a))
                                                          for a in arrays):
            raise InputValueError("sum_of_sines.amplitudes, frequencies and phases must be finite "
                                  f"with one shape (C, K); got {[a.shape for a in arrays]}")
        for name, a in zip(("amplitudes", "frequencies", "phases"), arrays):
            a.setflags(write=False)
            object.__setattr__(self, name, a)

    @classmethod
    def from_levels(cls, std, bandwidth: float, *, n_sines: int = 32, seed: int = 0):
        """Noise with standard deviations ``std`` (one per channel) spread over (0, bandwidth).

        Parameters
        ----------
        std : array_like, shape (C,)
            Root-mean-square value of each channel (e.g. rad and N m), >= 0.
        bandwidth : float
            Highest frequency, rad/s (> 0).
        n_sines : int, optional
            Sines per channel. Default 32.
        seed : int, optional
            Seed of the frequencies and phases. Default 0.
        """
        std = np.atleast_1d(check_array("sum_of_sines", "std", std, finite=False))
        if std.ndim != 1 or not np.all(np.isfinite(std)) or np.any(std < 0):
            raise InputValueError(f"sum_of_sines.std must be finite values >= 0; got {std!r}")
        bandwidth = check_real("sum_of_sines", "bandwidth", bandwidth, minimum=0.0, strict=True)
        rng = np.random.default_rng(seed)
        shape = (std.size, int(n_sines))
        freqs = rng.uniform(0.05, 1.0, shape) * bandwidth
        phases = rng.uniform(0.0, 2.0 * np.pi, shape)
        amps = np.repeat((std * np.sqrt(2.0 / n_sines))[:, None], n_sines, axis=1)
        return cls(amplitudes=amps, frequencies=freqs, phases=phases)

    def __call__(self, t: float) -> np.ndarray:
        """Noise at time ``t`` (s), shape (C,)."""
        return np.sum(self.amplitudes * np.sin(self.frequencies * float(t) + self.phases),
                      axis=1)

    def casadi(self, t):
        """The noise as a CasADi expression of the symbol ``t``, shape (C, 1).

        Parameters
        ----------
        t : casadi.SX or casadi.MX
            Scalar time, s.
        """
        import casadi as ca

        terms = ca.DM(self.amplitudes) * ca.sin(ca.DM(self.frequencies) * t
                                                + ca.DM(self.phases))
        return ca.sum2(terms)


@dataclass(frozen=True, kw_only=True, eq=False)
class LQG(ReferenceFeedback):
    """Output feedback: Kalman filter plus LQR (a :class:`flexctl.Controller`).

    Build with :func:`design_lqg`; see the module Notes for the equations and orders.

    Attributes
    ----------
    gain : ndarray, shape (1, n_d)
        LQR gain ``K``.
    estimator_gain : ndarray, shape (n_d, 2)
        Kalman gain ``L``.
    a, b, c : ndarray
        Design model ``A`` (n_d, n_d), ``B`` (n_d, 1), ``C`` (2, n_d) (theta, root_moment).
    measurement_matrix : ndarray, shape (2, 2 N + 2)
        Rows of the plant's output matrix that the sensors read.
    measurement_noise : callable, optional
        ``v(t)``, shape (2,), added to the measurements (e.g. :class:`SumOfSines`).
    reference, feedforward_inertia, torque_limit
        As in :class:`~controllers.feedback.lqr.LQR`.
    initial_estimate : ndarray, shape (n_d,), optional
        ``z(0)``; default zeros (the filter knows nothing of the initial state).
    deflection_gain : ndarray, shape (M,), optional
        As in :class:`~controllers.feedback.lqr.LQR`.
    layout : StateLayout, optional
        The design state's (and estimate's) layout, as in :class:`~controllers.feedback.lqr.LQR`.
    motor : DCMotor, optional
        The DC motor that turns the hub (its command a voltage,
        :class:`~controllers.feedback.actuated.MotorVoltage`): the torque is kept on the motor's
        voltage line at the estimated hub rate, ``|T + d w_hat| <= g V_max``, so that the
        filter integrates the torque the motor can give (anti-windup), not the one asked.
    plant_layout : StateLayout, optional
        The plant state's layout, set by :meth:`for_plant`; default None.
    """

    gain: np.ndarray
    estimator_gain: np.ndarray
    a: np.ndarray
    b: np.ndarray
    c: np.ndarray
    measurement_matrix: np.ndarray
    measurement_noise: object = None
    initial_estimate: np.ndarray = field(default=None, repr=False)
    deflection_gain: np.ndarray | None = field(default=None, repr=False)
    layout: StateLayout | None = field(default=None, repr=False)
    motor: object = field(default=None, repr=False)

    owner = "lqg"

    def __post_init__(self):
        nd = check_array("lqg", "a", self.a, finite=False, shape=(None, None)).shape[0]
        layout = gain_layout("lqg", self.layout, nd)
        # theta and each appendage's root moment
        nm = 1 + len(layout.appendages)
        shapes = {"gain": (1, nd), "estimator_gain": (nd, nm), "a": (nd, nd), "b": (nd, 1),
                  "c": (nm, nd)}
        for name, shape in shapes.items():
            value = check_array("lqg", name, getattr(self, name), finite=False).copy()
            if value.shape != shape or not np.all(np.isfinite(value)):
                raise InputValueError(f"lqg.{name} must be finite with shape {shape}; got "
                                      f"shape {value.shape}")
            value.setflags(write=False)
            object.__setattr__(self, name, value)
        object.__setattr__(self, "layout", layout)
        meas = check_array("lqg", "measurement_matrix", self.measurement_matrix,
                           finite=False).copy()
        if nm > 2:      # several appendages: the plant's layout tells its modes (for_plant)
            plant_modes = (layout.n_modes if meas.ndim == 2 and meas.shape[1] >= nd
                           else None)
        else:
            plant_modes = mode_count(layout, meas.shape[1]) if meas.ndim == 2 else None
        if plant_modes is None or meas.shape[0] != nm or plant_modes < layout.n_modes:
            raise InputValueError(f"lqg.measurement_matrix must have shape ({nm}, n) for a plant "
                                  f"of at least the design's modes (2 N + 2 states, N >= "
                                  f"{layout.n_modes} modes; got shape {meas.shape}")
        meas.setflags(write=False)
        object.__setattr__(self, "measurement_matrix", meas)
        if self.measurement_noise is not None and not callable(self.measurement_noise):
            raise InputTypeError("lqg.measurement_noise must be callable as v(t) -> shape (2,); "
                                 f"got {type(self.measurement_noise).__name__}")
        super().__post_init__()
        if self.initial_estimate is not None:
            z0 = check_array("lqg", "initial_estimate", self.initial_estimate,
                             finite=False).reshape(-1)
            if z0.shape != (nd,) or not np.all(np.isfinite(z0)):
                raise InputValueError(f"lqg.initial_estimate must be {nd} finite numbers; got "
                                      f"shape {z0.shape}")
            object.__setattr__(self, "initial_estimate", z0)

    @property
    def n_states(self) -> int:
        """Number of internal states, ``n_d = 2 M + 2``."""
        return self.a.shape[0]

    @property
    def n_modes(self) -> int:
        """Design modes ``M``."""
        return self.layout.n_modes

    def for_plant(self, model) -> "LQG":
        """The same controller reading the sensors of ``model`` (``N >= M`` modes).

        Parameters
        ----------
        model : flexctl.Model
            The plant the controller runs on.
        """
        model = checked_model("lqg.for_plant", model)
        if model.n_modes < self.n_modes:
            raise InputValueError(f"lqg.for_plant plant must have at least the design's "
                                  f"{self.n_modes} modes; got n_modes = {model.n_modes}")
        return replace(self, measurement_matrix=measurement_rows(model),
                       plant_layout=model.layout)

    def measure(self, t: float, x) -> np.ndarray:
        """Sensor readings ``[theta, root_moment]`` (rad, N m) of plant state ``x``.

        Parameters
        ----------
        t : float
            Time, s (where the measurement noise is evaluated).
        x : array_like, shape (n,)
            Plant state, in the order of the plant's layout (the plant of :meth:`for_plant`).

        Raises
        ------
        InputValueError
            If ``x`` is not of the length the sensors are set for.
        """
        x = np.asarray(x, dtype=float)
        if x.shape != (self.measurement_matrix.shape[1],):
            raise InputValueError(f"lqg: plant state has shape {x.shape} but the sensors are set "
                                  f"for {self.measurement_matrix.shape[1]} states; use "
                                  "lqg.for_plant(plant_model)")
        y = self.measurement_matrix @ x
        if self.measurement_noise is not None:
            y = y + np.asarray(self.measurement_noise(t), dtype=float).reshape(
                self.measurement_matrix.shape[0])
        return y

    def initial_state(self, x0) -> np.ndarray:
        """Initial estimate ``z(0)``, shape (n_d,).

        Parameters
        ----------
        x0 : array_like, shape (n,)
            Initial plant state (not read: the filter starts from :attr:`initial_estimate`,
            zeros by default).
        """
        if self.initial_estimate is None:
            return np.zeros(self.n_states)
        return self.initial_estimate.copy()

    def torque(self, t: float, x, z) -> float:
        """Hub torque, N m, from the estimate ``z``.

        Parameters
        ----------
        t : float
            Time, s.
        x : array_like, shape (n,)
            Plant state (not read).
        z : array_like, shape (n_d,)
            The estimate, in the order of :attr:`layout`.
        """
        x_ref, acc = reference_state(self.reference, t, self.layout, self.deflection_gain)
        z = np.asarray(z, dtype=float)
        u = self._apply(-float(self.gain[0] @ (z - x_ref)), acc)
        if self.motor is None:
            return u
        rate, reach = float(z[self.layout.theta_dot]), self._motor_reach()
        drag = self.motor.damping * rate
        return float(np.clip(u, -reach - drag, reach - drag))

    def _motor_reach(self) -> float:
        """``g V_max``: the torque the motor's voltage limit gives at standstill, N m."""
        return self.motor.torque_gain * self.motor.voltage_limit

    def derivative(self, t: float, x, z) -> np.ndarray:
        """``dz/dt = A z + B u + L (y - C z)``, shape (n_d,).

        Parameters
        ----------
        t : float
            Time, s.
        x : array_like, shape (n,)
            Plant state, read through the sensors (:meth:`measure`).
        z : array_like, shape (n_d,)
            The estimate, in the order of :attr:`layout`.
        """
        z = np.asarray(z, dtype=float)
        u = self.torque(t, x, z)
        innovation = self.measure(t, x) - self.c @ z
        return self.a @ z + self.b[:, 0] * u + self.estimator_gain @ innovation

    @property
    def has_casadi_form(self) -> bool:
        """True when the reference and the measurement noise (if any) have CasADi forms."""
        return has_casadi(self.reference) and has_casadi(self.measurement_noise, "casadi")

    def casadi_measure(self, t, x):
        """:meth:`measure` of the CasADi symbols ``t`` and ``x``, shape (2, 1).

        Parameters
        ----------
        t : CasADi scalar
            Time, s.
        x : CasADi column, shape (n, 1)
            Plant state, in the order of the plant's layout.
        """
        import casadi as ca

        if x.numel() != self.measurement_matrix.shape[1]:
            raise InputValueError(f"lqg: plant state has shape {x.shape} but the sensors are set "
                                  f"for {self.measurement_matrix.shape[1]} states; use "
                                  "lqg.for_plant(plant_model)")
        y = ca.mtimes(ca.DM(self.measurement_matrix), x)
        if self.measurement_noise is not None:
            y = y + self.measurement_noise.casadi(t)
        return y

    def casadi_torque(self, t, x, z):
        """:meth:`torque` as a CasADi expression of the symbols ``t``, ``x`` and ``z``.

        Parameters
        ----------
        t : CasADi scalar
            Time, s.
        x : CasADi column, shape (n, 1)
            Plant state (not read).
        z : CasADi column, shape (n_d, 1)
            The estimate.
        """
        import casadi as ca

        x_ref, acc = casadi_reference_state(self.reference, t, self.layout,
                                            self.deflection_gain)
        u = self._casadi_apply(-ca.dot(ca.DM(self.gain[0]), z - x_ref), acc)
        if self.motor is None:
            return u
        reach, drag = self._motor_reach(), self.motor.damping * z[self.layout.theta_dot]
        return ca.fmin(ca.fmax(u, -reach - drag), reach - drag)

    def casadi_derivative(self, t, x, z):
        """:meth:`derivative` as a CasADi expression, shape (n_d, 1).

        Parameters
        ----------
        t : CasADi scalar
            Time, s.
        x : CasADi column, shape (n, 1)
            Plant state, read through the sensors.
        z : CasADi column, shape (n_d, 1)
            The estimate.
        """
        import casadi as ca

        u = self.casadi_torque(t, x, z)
        innovation = self.casadi_measure(t, x) - ca.mtimes(ca.DM(self.c), z)
        return (ca.mtimes(ca.DM(self.a), z) + ca.DM(self.b[:, 0]) * u
                + ca.mtimes(ca.DM(self.estimator_gain), innovation))

    def compensator(self):
        """Linear compensator from ``[theta, root_moment]`` to torque (no reference, no
        saturation), a ``control.StateSpace`` with ``n_d`` states."""
        import control

        a = self.a - self.b @ self.gain - self.estimator_gain @ self.c
        measured = self.c.shape[0]
        inputs = (list(MEASURED_OUTPUTS) if measured == 2
                  else ["theta"] + [f"root_moment_{k}" for k in range(1, measured)])
        return control.ss(a, self.estimator_gain, -self.gain, np.zeros((1, measured)),
                          inputs=inputs, outputs=["torque"], name="lqg")

    def closed_loop_matrix(self, model, spin_rate: float = 0.0) -> np.ndarray:
        """``A`` of ``model.linearize(spin_rate)`` under this compensator, states ``[x, z]``,
        shape (2 N + 2 + n_d, 2 N + 2 + n_d).

        Parameters
        ----------
        model : flexctl.Model
            The plant (``N >= M`` modes).
        spin_rate : float, optional
            Steady hub rate of the plant's linearisation, rad/s. Default 0.
        """
        model = checked_model("lqg.closed_loop_matrix", model)
        meas = self.for_plant(model).measurement_matrix
        a_p, b_p = model.linear_matrices(spin_rate)
        top = np.hstack((a_p, -b_p @ self.gain))
        bottom = np.hstack((self.estimator_gain @ meas,
                            self.a - self.b @ self.gain - self.estimator_gain @ self.c))
        return np.vstack((top, bottom))

    def closed_loop_poles(self, model, spin_rate: float = 0.0) -> np.ndarray:
        """Poles of :meth:`closed_loop_matrix`, shape (2 N + 2 + n_d,), 1/s.

        Parameters
        ----------
        model : flexctl.Model
            The plant (``N >= M`` modes).
        spin_rate : float, optional
            Steady hub rate of the plant's linearisation, rad/s. Default 0.
        """
        return np.linalg.eigvals(self.closed_loop_matrix(model, spin_rate))


def design_lqg(model, weights: LQRWeights, noise: NoiseLevels, spin_rate: float = 0.0, *,
               plant=None, reference=None, feedforward: bool = True,
               torque_limit: float | None = None, measurement_noise=None,
               flexible_reference: bool = True, estimate_plant_modes: bool = True,
               check_stability: bool = True) -> LQG:
    """LQR gain on ``model.linearize(spin_rate)`` and a Kalman filter of the plant's modes.

    The regulator acts on the design model's ``M`` modes. The filter, given a ``plant`` of
    ``N > M`` modes, models all ``N`` of them (``estimate_plant_modes``): the root moment
    reads every mode, and a filter that knows only ``M`` of them feeds the rest back through
    its innovation (observation spillover), which destabilises the undamped modes above
    ``M`` (on slew-90's 6-mode plant the third mode grows at 0.024 1/s). Knowing them, the
    filter's error is independent of the loop, and the closed loop's poles are the
    regulator's (the lifted gain ``K P`` on the plant) and the filter's.

    Parameters
    ----------
    model : flexctl.Model
        Design model (``M`` modes).
    weights : LQRWeights
        Regulator weights (see :func:`controllers.feedback.lqr.lqr_weight_matrices`).
    noise : NoiseLevels
        Noise the filter is designed for.
    spin_rate : float, optional
        Steady hub rate of the design linearisation, rad/s. Default 0.
    plant : flexctl.Model, optional
        Model whose sensors the controller reads in simulation (``N >= M`` modes). Default:
        ``model``.
    reference : object, optional
        Hub reference, as in :func:`controllers.feedback.lqr.design_lqr`.
    feedforward : bool, optional
        Add ``J0 acc_ref``, as in :func:`controllers.feedback.lqr.design_lqr`. Default True.
    torque_limit : float, optional
        Saturation, N m, as in :func:`controllers.feedback.lqr.design_lqr`.
    measurement_noise : callable, optional
        ``v(t)`` added to the measurements in simulation, shape (2,).
    flexible_reference : bool, optional
        As in :func:`controllers.feedback.lqr.design_lqr`. Default True.
    estimate_plant_modes : bool, optional
        Model every mode of ``plant`` in the filter (default True); False models the design
        model's modes only (cheaper, and unstable on an undamped plant with more modes).
    check_stability : bool, optional
        Check the loop on ``plant`` (:func:`controllers.design.stability.check_loop`) and warn
        (:class:`~controllers.design.stability.LoopStabilityWarning`) when it is unstable or nearly
        so. Default True.

    Returns
    -------
    LQG
        Its estimate ``z`` has the layout of the filter's model: the design model's, or the
        plant's mode count on the design model's variant.

    Examples
    --------
    >>> import flexctl
    >>> from controllers.feedback.lqr import LQRWeights
    >>> model = flexctl.build_model(flexctl.load_scene("hub-beam-mass").system, n_modes=2)
    >>> lqg = design_lqg(model, LQRWeights(hub_angle=0.1, hub_rate=0.02, torque=2.0),
    ...                  NoiseLevels(angle=1e-3, root_moment=0.1, torque=1.0))
    >>> lqg.n_states, bool(lqg.closed_loop_poles(model).real.max() < 0)
    (6, True)
    """
    model = checked_model("design_lqg", model)
    spin_rate = check_real("design_lqg", "spin_rate", spin_rate)
    if not isinstance(weights, LQRWeights):
        raise InputTypeError(f"design_lqg.weights must be LQRWeights; got "
                             f"{type(weights).__name__}")
    with design_failure("lqg", "design_lqg", model, spin_rate, weights=weights):
        gain, _ = lqr_gain(model, weights, spin_rate)
    filtered = _filter_model(model, plant) if estimate_plant_modes else model
    gain = gain @ truncation_matrix(filtered.layout, model.layout)
    est_gain, _ = estimator_gain(filtered, noise, spin_rate)
    a, b = filtered.linear_matrices(spin_rate)
    controller = LQG(gain=gain, estimator_gain=est_gain, a=a, b=b,
                     c=measurement_rows(filtered), measurement_matrix=measurement_rows(filtered),
                     measurement_noise=measurement_noise, reference=reference,
                     feedforward_inertia=float(model.rigid_inertia) if feedforward else None,
                     torque_limit=torque_limit,
                     deflection_gain=(static_deflection_gain(filtered) if flexible_reference
                                      else None), layout=filtered.layout)
    if plant is None:
        return controller
    controller = controller.for_plant(plant)
    return checked_on(controller, plant) if check_stability else controller


def _filter_model(model, plant):
    """The design model on the plant's modes (the model itself when the plant has no more)."""
    if plant is None:
        return model
    plant = checked_model("design_lqg.plant", plant)
    if plant.layout.n_modes <= model.layout.n_modes:
        return model
    from flexctl.model.build import rebuild

    spec = plant.mode_spec
    if isinstance(model.mode_spec, int) and not isinstance(spec, int):
        spec = int(sum(spec))       # one beam's design for a plant built as a structure
    return rebuild(model, n_modes=spec)
