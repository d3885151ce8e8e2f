"""The attitude filters (:mod:`controllers.feedback.mekf`,
:mod:`controllers.feedback.flexible_mekf`) as CasADi step functions, and their compiled C as
the estimator of the spatial loop.

One step is one gyro sample with its star tracker reading, if any:

- **The attitude filter** (:class:`~controllers.feedback.mekf.AttitudeFilter`). Input ``v``
  (:data:`FILTER_INPUTS`): the gyro's reading over the sample just past ``gx gy gz``
  (rad/s), the star tracker's ``sw sx sy sz`` and ``tracked`` (1 when that reading is new at
  this sample, else 0). Output: the estimate ``qw qx qy qz bx by bz`` (the rate a law reads
  is the gyro's reading less the bias).
- **The filter with the modes**
  (:class:`~controllers.feedback.flexible_mekf.FlexibleAttitudeFilter`). Input
  (:data:`FLEXIBLE_FILTER_INPUTS`): the gyro's reading, the torque on the structure over the
  sample ``tx ty tz`` (N m), the wheels' momentum at its start ``hx hy hz`` (N m s, zero
  without wheels), then the tracker's reading and ``tracked``. Output: the attitude and
  bias, then the flexible state (the filter's ``names``: modal coordinates, hub rate, modal
  rates; the modes it leaves out at zero). The model's nonlinear remainder is written out as
  expressions.

Memory of both: the estimate ``q, b`` (and the filtered modal part ``z``), its covariance
``P`` (by rows), the propagations done (up to the latency's) and, per gyro sample of the
tracker's latency, the estimate before it and that sample's inputs (the filter's history).
The step propagates and then, with ``tracked``, updates with the tracker's reading, going back
``latency`` samples and propagating again as the filters do.

:func:`compiled_attitude_filter` turns a compiled filter back into an estimator of
:func:`flexctl.sim.spatial_loop.simulate_spatial_loop`: this is how the C is checked
against Python in the loop.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from flexctl.model.checks import check_array, check_quaternion
from flexctl.model.errors import InputTypeError, InputValueError
from flexctl.sim.quaternions import (symbolic_from_rotation_vector, symbolic_product,
                                     symbolic_rotation_matrix, symbolic_rotation_vector)

from .program import ControllerProgram, ExportRefused

__all__ = ["filter_program", "compiled_attitude_filter", "CompiledAttitudeFilter",
           "FILTER_INPUTS", "FLEXIBLE_FILTER_INPUTS", "FILTER_OUTPUTS", "MAX_FILTER_LAG"]

#: The attitude filter program's input: the gyro reading, the star tracker reading, whether it
#: is new.
FILTER_INPUTS = ("gx", "gy", "gz", "sw", "sx", "sy", "sz", "tracked")
#: The input of the filter with the modes: the gyro reading, the torque on the structure, the
#: wheels' momentum, the star tracker reading, whether it is new.
FLEXIBLE_FILTER_INPUTS = ("gx", "gy", "gz", "tx", "ty", "tz", "hx", "hy", "hz", "sw", "sx",
                          "sy", "sz", "tracked")
#: The filter programs' output: the estimated attitude and gyro bias (then, with the modes,
#: the flexible state).
FILTER_OUTPUTS = ("qw", "qx", "qy", "qz", "bx", "by", "bz")
#: Most gyro samples of star tracker latency a filter program replays (its code grows with it).
MAX_FILTER_LAG = 20


@dataclass(frozen=True)
class _Layout:
    """A filter program's memory: ``q`` (4), ``b`` (3), ``z`` (``modal``), ``P`` (``N x N``
    by rows, ``N = 6 + modal``), the propagations done, and ``lag`` history entries of
    ``(q, b, z, P, the sample's inputs)`` (``inputs`` numbers)."""

    modal: int
    lag: int
    inputs: int

    @property
    def size(self) -> int:
        return 6 + self.modal

    @property
    def state(self) -> int:
        return 7 + self.modal + self.size ** 2

    @property
    def entry(self) -> int:
        return self.state + self.inputs

    @property
    def total(self) -> int:
        return self.state + 1 + self.lag * self.entry

    def estimate(self, ca, vector) -> tuple:
        """``(q, b, z, P)`` from the first :attr:`state` numbers of ``vector``."""
        r, n = self.modal, self.size
        return (vector[0:4], vector[4:7], vector[7:7 + r],
                ca.reshape(vector[7 + r:self.state], n, n).T)

    def split(self, ca, memory) -> tuple:
        """``(q, b, z, P, done, history)`` of the memory."""
        return (*self.estimate(ca, memory), memory[self.state], memory[self.state + 1:])

    def packed(self, ca, q, b, z, cov) -> object:
        """The estimate ``(q, b, z, P)`` as one column (``P`` by rows)."""
        return ca.vertcat(q, b, z, ca.reshape(cov.T, self.size ** 2, 1))

    def joined(self, ca, state) -> object:
        """The memory of ``(q, b, z, P, done, history)``."""
        *estimate, done, history = state
        return ca.vertcat(self.packed(ca, *estimate), done, history)

    def initial(self, estimator) -> np.ndarray:
        memory = np.zeros(self.total)
        memory[0:4], memory[4:7] = estimator.q, estimator.b
        memory[7:7 + self.modal] = getattr(estimator, "x", np.zeros(0))
        memory[7 + self.modal:self.state] = np.asarray(estimator.P, dtype=float).reshape(-1)
        return memory


def _remembered(ca, state, inputs, layout: _Layout) -> tuple:
    """``state`` with the estimate before this sample and its inputs pushed on the history."""
    q, b, z, cov, done, history = state
    if not layout.lag:
        return state
    entry = ca.vertcat(layout.packed(ca, q, b, z, cov), inputs)
    return (q, b, z, cov, ca.fmin(done + 1, layout.lag),
            ca.vertcat(history[layout.entry:], entry))


def _tracker_update(ca, state, measured, layout: _Layout, covariance, propagate):
    """CasADi: a star tracker update of ``state``, as :meth:`AttitudeFilter.update
    <controllers.feedback.mekf.AttitudeFilter.update>` (back ``lag`` samples and forward)."""
    q, b, z, cov, done, history = state
    replayed = []
    if layout.lag:
        q, b, z, cov = layout.estimate(ca, history[0:layout.state])
        replayed = [history[k * layout.entry + layout.state:(k + 1) * layout.entry]
                    for k in range(layout.lag)]
        history = ca.SX.zeros(history.numel())
    residual = symbolic_rotation_vector(symbolic_product(ca.vertcat(q[0], -q[1:4]),
                                                         measured / ca.norm_2(measured)))
    gain = ca.mtimes(cov[:, 0:3], ca.inv(cov[0:3, 0:3] + ca.DM(covariance)))
    correction = ca.mtimes(gain, residual)
    q = symbolic_product(q, symbolic_from_rotation_vector(correction[0:3]))
    q = q / ca.norm_2(q)
    b = b + correction[3:6]
    z = z + correction[6:]
    keep = ca.SX.eye(layout.size)
    keep[:, 0:3] -= gain
    cov = ca.mtimes([keep, cov, keep.T]) + ca.mtimes([gain, ca.DM(covariance), gain.T])
    state = (q, b, z, cov, 0.0 if layout.lag else done, history)
    for inputs in replayed:
        state = propagate(state, inputs)
    return state


def _attitude_propagation(ca, estimator, layout: _Layout):
    """CasADi: :meth:`AttitudeFilter.propagate
    <controllers.feedback.mekf.AttitudeFilter.propagate>` of ``(state, reading)``."""
    step = float(estimator.step)
    sigma_v2, sigma_u2 = float(estimator.sigma_v) ** 2, float(estimator.sigma_u2)
    noise = np.zeros((6, 6))
    noise[:3, :3] = (sigma_v2 * step + sigma_u2 * step ** 3 / 3) * np.eye(3)
    noise[:3, 3:] = noise[3:, :3] = -sigma_u2 * step * step / 2 * np.eye(3)
    noise[3:, 3:] = sigma_u2 * step * np.eye(3)

    def propagate(state, reading):
        q, b, z, cov, done, history = _remembered(ca, state, reading, layout)
        w = reading - b
        q = symbolic_product(q, symbolic_from_rotation_vector(w * step))
        q = q / ca.norm_2(q)
        phi = ca.SX.eye(6)
        phi[0:3, 0:3] = symbolic_rotation_matrix(symbolic_from_rotation_vector(-w * step))
        phi[0:3, 3:6] = -step * ca.SX.eye(3) + 0.5 * step * step * ca.skew(w)
        cov = ca.mtimes([phi, cov, phi.T]) + ca.DM(noise)
        return q, b, z, 0.5 * (cov + cov.T), done, history
    return propagate


def _right_jacobian(ca, phi):
    """CasADi: :func:`controllers.feedback.flexible_mekf` 's ``J_r(phi)``, its series below
    1e-6 rad."""
    angle = ca.norm_2(phi)
    k = ca.skew(phi)
    k2 = ca.mtimes(k, k)
    safe = ca.fmax(angle, 1e-6)
    return ca.if_else(angle < 1e-6, ca.SX.eye(3) - 0.5 * k + k2 / 6.0,
                      ca.SX.eye(3) - (1 - ca.cos(safe)) / safe ** 2 * k
                      + (safe - ca.sin(safe)) / safe ** 3 * k2)


def _flexible_propagation(ca, estimator, layout: _Layout):
    """CasADi: :meth:`FlexibleAttitudeFilter.propagate
    <controllers.feedback.flexible_mekf.FlexibleAttitudeFilter.propagate>` of ``(state,
    inputs)``, ``inputs`` the gyro reading, the torque and the wheels' momentum."""
    from ..slew.spatial_trajopt import remainder_expression

    t, n = float(estimator.step), layout.size
    basis = ca.DM(estimator.part.basis)
    at = estimator.model.rate_at
    phi0, gamma, s_x0, s_u = (ca.DM(estimator.phi), ca.DM(estimator.gamma),
                              ca.DM(estimator.s_x), ca.DM(estimator.s_u))
    gamma_r, s_r = ca.DM(estimator.gamma_r), ca.DM(estimator.s_r)
    d_q, reading_noise = ca.DM(estimator.disturbance_cross), ca.DM(estimator.reading_noise)
    walk, variance = ca.DM(estimator.bias_walk), float(estimator.torque_variance)
    # the remainder once in the C, called at each propagation (the replays' included)
    x, torque = ca.SX.sym("x", basis.shape[0]), ca.SX.sym("torque", 3)
    remainder = ca.Function("flexctl_remainder", [x, torque],
                            [remainder_expression(estimator.model, x, torque)],
                            {"never_inline": True, "cse": True})

    def propagate(state, inputs):
        q, b, z, cov, done, history = _remembered(ca, state, inputs, layout)
        reading, u, momentum = inputs[0:3], inputs[3:6], inputs[6:9]
        coupling = ca.mtimes(ca.skew(momentum), basis[at:at + 3, :])
        phi = phi0 + ca.mtimes(gamma, coupling)
        s_x = s_x0 + ca.mtimes(s_u, coupling)
        h = ca.horzcat(ca.SX.zeros(3, 3), ca.SX.eye(3), s_x / t)
        rest = remainder(ca.mtimes(basis, z), u)
        turned = ca.mtimes(s_x, z) + ca.mtimes(s_u, u) + ca.mtimes(s_r, rest)
        j_r = _right_jacobian(ca, turned)
        f = ca.SX.eye(n)
        f[0:3, 0:3] = symbolic_rotation_matrix(symbolic_from_rotation_vector(-turned))
        f[0:3, 6:] = ca.mtimes(j_r, s_x)
        f[6:, 6:] = phi
        g = ca.vertcat(ca.mtimes(j_r, s_u), ca.SX.zeros(3, 3), gamma)
        innovation_cov = ca.mtimes([h, cov, h.T]) + reading_noise
        cross = ca.mtimes([f, cov, h.T]) + ca.mtimes(g, d_q)
        gain = ca.solve(innovation_cov, cross.T).T
        innovation = reading - (turned / t + b)
        q = symbolic_product(q, symbolic_from_rotation_vector(turned))
        z = ca.mtimes(phi, z) + ca.mtimes(gamma, u) + ca.mtimes(gamma_r, rest)
        correction = ca.mtimes(gain, innovation)
        q = symbolic_product(q, symbolic_from_rotation_vector(correction[0:3]))
        q = q / ca.norm_2(q)
        b = b + correction[3:6]
        z = z + correction[6:]
        cov = (ca.mtimes([f, cov, f.T]) + variance * ca.mtimes(g, g.T) + walk
               - ca.mtimes([gain, innovation_cov, gain.T]))
        return q, b, z, 0.5 * (cov + cov.T), done, history
    return propagate


def filter_program(estimator) -> ControllerProgram:
    """The :class:`~controllers.codegen.program.ControllerProgram` of an attitude filter, or
    of the one with the modes: one gyro sample per step (module description).

    Parameters
    ----------
    estimator : AttitudeFilter or FlexibleAttitudeFilter
        The filter, in the state it starts from (its estimate and covariance; a filter that
        has propagated already is refused).

    Returns
    -------
    ControllerProgram
        ``kind = "mekf"`` (input :data:`FILTER_INPUTS`) or ``"flexible_mekf"`` (input
        :data:`FLEXIBLE_FILTER_INPUTS`); output :data:`FILTER_OUTPUTS` (and the flexible
        state).

    Raises
    ------
    ExportRefused
        If the tracker's latency spans more than :data:`MAX_FILTER_LAG` gyro samples, or the
        filter has a history.
    """
    import casadi as ca

    from ..feedback.flexible_mekf import FlexibleAttitudeFilter
    from ..feedback.mekf import AttitudeFilter

    if not isinstance(estimator, AttitudeFilter):
        raise InputTypeError(f"filter_program takes an AttitudeFilter or a "
                             f"FlexibleAttitudeFilter; got {type(estimator).__name__}")
    lag = estimator.lag
    if lag > MAX_FILTER_LAG:
        raise ExportRefused(f"export: the star tracker's latency spans {lag} gyro samples, "
                            f"more than {MAX_FILTER_LAG}: the filter's C replays each of them "
                            "at an update")
    if len(estimator.history):
        raise ExportRefused(f"export: the filter has propagated already; export it as it "
                            f"starts (a new {type(estimator).__name__})")
    flexible = isinstance(estimator, FlexibleAttitudeFilter)
    if flexible:
        layout = _Layout(modal=estimator.x.size, lag=lag, inputs=9)
        propagate, names = _flexible_propagation(ca, estimator, layout), FLEXIBLE_FILTER_INPUTS
    else:
        layout = _Layout(modal=0, lag=lag, inputs=3)
        propagate, names = _attitude_propagation(ca, estimator, layout), FILTER_INPUTS
    sample = layout.inputs
    t, v, m = ca.SX.sym("t"), ca.SX.sym("v", len(names)), ca.SX.sym("m", layout.total)
    moved = propagate(layout.split(ca, m), v[0:sample])
    updated = _tracker_update(ca, moved, v[sample:sample + 4], layout,
                              np.asarray(estimator.R, dtype=float), propagate)
    ready = v[sample + 4] > 0.5
    if lag:
        ready = ca.logic_and(ready, moved[4] >= lag - 0.5)
    chosen = tuple(ca.if_else(ready, new, old) for new, old in zip(updated, moved))
    q, b, z = chosen[0:3]
    output = ca.vertcat(q, b, ca.mtimes(ca.DM(estimator.part.basis), z)) if flexible \
        else ca.vertcat(q, b)
    step = ca.Function("step", [t, v, m], [output, layout.joined(ca, chosen)],
                       ["t", "v", "m"], ["u", "m_next"])
    step_time = float(estimator.step)
    common = dict(step=step, recover=None, input_names=names, input_kind="measurement",
                  output_name="estimate", memory_init=layout.initial(estimator),
                  sample_time=step_time)
    if not flexible:
        return ControllerProgram(
            kind="mekf", **common,
            output_unit="attitude (scalar first) and gyro bias (rad/s)",
            description=(f"multiplicative extended Kalman filter of attitude and gyro bias, "
                         f"one gyro sample ({step_time:g} s) per step, star tracker latency "
                         f"{lag} samples"),
            info={"latency_samples": lag})
    return ControllerProgram(
        kind="flexible_mekf", **common,
        output_unit=("attitude (scalar first), gyro bias (rad/s), then the flexible state "
                     + ", ".join(estimator.names)),
        description=(f"multiplicative extended Kalman filter of attitude, gyro bias and "
                     f"{layout.modal} modal states of the structure, driven by the torque, "
                     f"one gyro sample ({step_time:g} s) per step, star tracker latency "
                     f"{lag} samples"),
        info={"latency_samples": lag, "flexible_state": list(estimator.names),
              "modal_states": layout.modal})


def _checked(compiled, v) -> np.ndarray:
    u, code = compiled.step(0.0, v)
    if code != 0:
        raise RuntimeError(f"compiled filter returned code {code}")
    return u


class CompiledAttitudeFilter:
    """A compiled :func:`filter_program` as the estimator of
    :func:`flexctl.sim.spatial_loop.simulate_spatial_loop` (``propagate``, ``update``,
    ``attitude``, ``bias``, ``lag``; the filter with the modes also ``takes_torque`` and
    ``flexible_state``): made by :func:`compiled_attitude_filter`.

    A step of the C filter is one gyro sample with its tracker reading, if any: a
    :meth:`propagate` is held until the estimate is read or an :meth:`update` joins it, so an
    update always follows a propagation.

    Parameters
    ----------
    compiled : CompiledLaw
        The compiled filter, started here (``flexctl_ctrl_init``).
    """

    def __init__(self, compiled):
        self.compiled = compiled
        program = compiled.program
        self.lag = int(program.info.get("latency_samples", 0))
        #: True for the filter with the modes (the loop hands it the torque).
        self.takes_torque = program.kind == "flexible_mekf"
        size = len(program.info.get("flexible_state", ()))
        self._estimate = np.concatenate([program.memory_init[0:7], np.zeros(size)])
        self._pending = None
        compiled.init()

    def _run(self, inputs, measured) -> None:
        v = np.concatenate([inputs, np.zeros(4) if measured is None else measured,
                            [0.0 if measured is None else 1.0]])
        self._estimate = np.array(_checked(self.compiled, v), dtype=float)
        self._pending = None

    def _flush(self) -> None:
        if self._pending is not None:
            self._run(self._pending, None)

    def propagate(self, gyro_reading, torque=None, wheel_momentum=None) -> None:
        """Advance by one gyro sample (held until the estimate is read or an update joins it).

        Parameters
        ----------
        gyro_reading : array_like, shape (3,)
            The gyro's reading over the sample, rad/s.
        torque : array_like, shape (3,), optional
            The filter with the modes: the torque on the structure over the sample, N m
            (default zero); refused by the attitude filter.
        wheel_momentum : array_like, shape (3,), optional
            The filter with the modes: the wheels' momentum at the sample's start, N m s
            (default zero); refused by the attitude filter.
        """
        owner = "compiled_filter"
        inputs = [check_array(owner, "gyro_reading", gyro_reading, shape=(3,))]
        if self.takes_torque:
            for name, value in (("torque", torque), ("wheel_momentum", wheel_momentum)):
                inputs.append(np.zeros(3) if value is None
                              else check_array(owner, name, value, shape=(3,)))
        elif torque is not None or wheel_momentum is not None:
            raise InputValueError("the compiled attitude filter integrates the gyro: it takes "
                                  "no torque or wheel momentum")
        self._flush()
        self._pending = np.concatenate(inputs).astype(float)

    def update(self, measured) -> None:
        """Take a star tracker reading with the gyro sample just propagated.

        Parameters
        ----------
        measured : array_like, shape (4,)
            The reading, hub to inertial, scalar first.

        Raises
        ------
        InputValueError
            If no propagation comes before it (the C filter updates within a gyro sample), or
            the reading is not a non-zero quaternion.
        """
        q_m = np.array(check_quaternion("compiled_filter", "measured", measured), dtype=float)
        if self._pending is None:
            raise InputValueError("the compiled filter takes a star tracker reading within a "
                                  "gyro sample: propagate first")
        self._run(self._pending, q_m)

    @property
    def attitude(self) -> np.ndarray:
        """Estimated attitude, hub to inertial, scalar first, shape (4,)."""
        self._flush()
        return self._estimate[0:4].copy()

    @property
    def bias(self) -> np.ndarray:
        """Estimated gyro bias, rad/s, shape (3,)."""
        self._flush()
        return self._estimate[4:7].copy()

    @property
    def flexible_state(self) -> np.ndarray:
        """The filter with the modes: its estimated flexible state (the filter's ``names``),
        shape (n,); empty for the attitude filter."""
        self._flush()
        return self._estimate[7:].copy()


def compiled_attitude_filter(compiled) -> CompiledAttitudeFilter:
    """A compiled attitude filter, or filter with the modes
    (:meth:`controllers.codegen.export.CExport.compile` of a :func:`filter_program`), as the
    estimator of :func:`flexctl.sim.spatial_loop.simulate_spatial_loop`.

    Parameters
    ----------
    compiled : CompiledLaw
        The compiled export.

    Returns
    -------
    CompiledAttitudeFilter
    """
    kind = getattr(getattr(compiled, "program", None), "kind", None)
    if kind not in ("mekf", "flexible_mekf"):
        raise InputTypeError(f"compiled_attitude_filter takes a compiled attitude filter; got "
                             f"{kind or type(compiled).__name__}")
    return CompiledAttitudeFilter(compiled)
