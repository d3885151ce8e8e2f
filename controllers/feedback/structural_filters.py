"""Structural filters in a sampled loop: notch, second-order roll-off and lead-lag.

An attitude loop on a flexible structure shapes its command so that the modes it cannot
control well are not excited: a notch attenuates the command at one modal frequency, a
roll-off everything above a corner, a lead-lag adds phase near the crossover. Each filter is
designed in continuous time, with unit gain at zero frequency, and discretised at the loop's
sample time by the matched pole-zero method (each pole and zero ``s`` mapped to
``exp(s T)``, the zeros at infinity to ``z = -1``, the gain matched at zero frequency).

:class:`Filtered` puts a cascade of them behind a sampled law, between its command and the
plant's input: the simulation steps the filters once per sample
(:class:`~flexctl.sim.digital.SampledController`), :func:`controllers.loop_transfer` gives the
loop ``F(z) L(z)`` and :func:`controllers.check_loop` judges the closed loop with the filters'
states.

Examples
--------
>>> f = Notch(frequency=20.0, depth_db=20.0, width=0.2)
>>> w = [0.0, 20.0]
>>> [round(float(abs(v)), 6) for v in f.response(w)]                # unit at 0, -20 dB at 20 rad/s
[1.0, 0.1]
>>> [round(float(abs(v)), 3) for v in f.response(w, sample_time=0.01)]
[1.0, 0.1]
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from flexctl.model.checks import KeywordOnly, check_real
from flexctl.model.errors import InputTypeError, InputValueError

__all__ = ["Notch", "RollOff", "LeadLag", "FilterCascade", "Filtered", "FILTER_KINDS"]

#: Highest frequency of a filter's pole or zero, as a fraction of the Nyquist frequency
#: ``pi / T``: above it the matched map folds the filter onto another frequency.
NYQUIST_FRACTION = 0.9
#: The frequencies a filter may have, rad/s.
FREQUENCY_RANGE = (1e-6, 1e9)


class _Filter:
    """What the three filters share: their continuous polynomials and what follows."""

    def continuous(self) -> tuple:
        """``(num, den)``: the transfer function's polynomials in ``s`` (highest power first),
        unit gain at zero frequency."""
        raise NotImplementedError

    def _fastest(self) -> float:
        """The largest magnitude of a pole or zero, rad/s."""
        num, den = self.continuous()
        return float(max(np.max(np.abs(np.roots(num)), initial=0.0),
                         np.max(np.abs(np.roots(den)), initial=0.0)))

    def discrete(self, sample_time: float) -> tuple:
        """``(num, den)``: the matched pole-zero discretisation, polynomials in ``z`` of equal
        degree (highest power first), unit gain at ``z = 1``.

        Parameters
        ----------
        sample_time : float
            The loop's sample time ``T``, s: every pole and zero below
            :data:`NYQUIST_FRACTION` of ``pi / T``.

        Raises
        ------
        InputValueError
            If a pole or zero of the filter lies at or above that frequency.
        """
        step = check_real(type(self).__name__, "sample_time", sample_time, minimum=0.0,
                          strict=True)
        fastest, limit = self._fastest(), NYQUIST_FRACTION * math.pi / step
        if fastest >= limit:
            raise InputValueError(
                f"{type(self).__name__} has a pole or zero at {fastest:.4g} rad/s, above "
                f"{NYQUIST_FRACTION:g} of the Nyquist frequency {math.pi / step:.4g} rad/s of "
                f"the {step:g} s sample time: the sampled loop cannot shape it; lower the "
                "filter's frequency or the sample time")
        num, den = self.continuous()
        zeros, poles = np.roots(num), np.roots(den)
        z_zeros = np.concatenate((np.exp(zeros * step), -np.ones(poles.size - zeros.size)))
        num_z, den_z = np.real(np.poly(z_zeros)), np.real(np.poly(np.exp(poles * step)))
        return num_z * (np.polyval(den_z, 1.0) / np.polyval(num_z, 1.0)), den_z

    def response(self, frequencies, sample_time: float | None = None) -> np.ndarray:
        """The complex frequency response at ``frequencies`` (rad/s): of the continuous
        filter, or of its discretisation at ``sample_time``.

        Parameters
        ----------
        frequencies : array_like
            Frequencies, rad/s (>= 0).
        sample_time : float, optional
            Sample time, s. Default: the continuous filter.
        """
        w = np.asarray(frequencies, dtype=float)
        if sample_time is None:
            num, den = self.continuous()
            s = 1j * w
        else:
            num, den = self.discrete(sample_time)
            s = np.exp(1j * w * sample_time)
        return np.polyval(num, s) / np.polyval(den, s)


def _positive(owner: str, name: str, value) -> float:
    return check_real(owner, name, value, minimum=0.0, strict=True)


def _frequency(owner: str, name: str, value) -> float:
    """A filter frequency, rad/s, within :data:`FREQUENCY_RANGE` (beyond it the polynomials
    overflow or the gain match divides by zero)."""
    low, high = FREQUENCY_RANGE
    return check_real(owner, name, value, minimum=low, maximum=high)


@dataclass(frozen=True, kw_only=True)
class Notch(_Filter, KeywordOnly):
    """A notch: ``(s^2 + 2 zeta_z w s + w^2) / (s^2 + 2 zeta_p w s + w^2)``.

    Parameters
    ----------
    frequency : float
        Centre ``w``, rad/s (> 0).
    depth_db : float
        Attenuation at the centre, dB (> 0): ``|H(j w)| = zeta_z / zeta_p``.
    width : float, optional
        ``zeta_p``, the damping of the poles (> 0, at most 1): the notch is about
        ``2 zeta_p w`` wide between its half-depth points. Default 0.3.
    """

    frequency: float
    depth_db: float
    width: float = 0.3

    def __post_init__(self):
        object.__setattr__(self, "frequency", _frequency("Notch", "frequency", self.frequency))
        object.__setattr__(self, "depth_db", _positive("Notch", "depth_db", self.depth_db))
        object.__setattr__(self, "width", check_real("Notch", "width", self.width, minimum=0.0,
                                                     maximum=1.0, strict=True))

    def continuous(self) -> tuple:
        """``(num, den)`` in ``s``: the notch's polynomials, unit gain at zero frequency."""
        w, zeta_p = self.frequency, self.width
        zeta_z = zeta_p * 10.0 ** (-self.depth_db / 20.0)
        return np.array([1.0, 2 * zeta_z * w, w * w]), np.array([1.0, 2 * zeta_p * w, w * w])


@dataclass(frozen=True, kw_only=True)
class RollOff(_Filter, KeywordOnly):
    """A second-order low-pass: ``w^2 / (s^2 + 2 zeta w s + w^2)``.

    Parameters
    ----------
    frequency : float
        Corner ``w``, rad/s (> 0).
    damping : float, optional
        ``zeta`` (> 0, at most 2). Default 0.7.
    """

    frequency: float
    damping: float = 0.7

    def __post_init__(self):
        object.__setattr__(self, "frequency", _frequency("RollOff", "frequency", self.frequency))
        object.__setattr__(self, "damping", check_real("RollOff", "damping", self.damping,
                                                       minimum=0.0, maximum=2.0, strict=True))

    def continuous(self) -> tuple:
        """``(num, den)`` in ``s``: the roll-off's polynomials, unit gain at zero frequency."""
        w = self.frequency
        return np.array([w * w]), np.array([1.0, 2 * self.damping * w, w * w])


@dataclass(frozen=True, kw_only=True)
class LeadLag(_Filter, KeywordOnly):
    """A lead or lag: ``(s / zero + 1) / (s / pole + 1)``; a lead for ``zero < pole``.

    Parameters
    ----------
    zero : float
        Zero frequency, rad/s (> 0).
    pole : float
        Pole frequency, rad/s (> 0, not equal to ``zero``).
    """

    zero: float
    pole: float

    def __post_init__(self):
        object.__setattr__(self, "zero", _frequency("LeadLag", "zero", self.zero))
        object.__setattr__(self, "pole", _frequency("LeadLag", "pole", self.pole))
        if self.zero == self.pole:
            raise InputValueError(f"LeadLag.pole must differ from LeadLag.zero (a filter that "
                                  f"does nothing); got {self.pole!r}")

    def continuous(self) -> tuple:
        """``(num, den)`` in ``s``: the lead-lag's polynomials, unit gain at zero frequency."""
        return np.array([1.0 / self.zero, 1.0]), np.array([1.0 / self.pole, 1.0])


#: The filter kinds, by the name a table gives them.
FILTER_KINDS = {"notch": Notch, "roll_off": RollOff, "lead_lag": LeadLag}


@dataclass(frozen=True)
class FilterCascade:
    """Filters in series, discretised at one sample time, as one discrete state space.

    Parameters
    ----------
    filters : tuple of Notch, RollOff or LeadLag
        Applied in order (the order does not change the product).
    sample_time : float
        The loop's sample time, s.

    Attributes
    ----------
    a, b, c, d : ndarray
        ``x+ = A x + B u``, ``y = C x + D u``: shapes (n, n), (n, 1), (1, n), (1, 1), ``n``
        the sum of the filters' orders; ``x = 0`` is the filters at rest.
    """

    filters: tuple
    sample_time: float

    def __post_init__(self):
        filters = tuple(self.filters) if isinstance(self.filters, (tuple, list)) else None
        if not filters:
            raise InputValueError("filters must be a non-empty sequence of Notch, RollOff or "
                                  f"LeadLag; got {self.filters!r}")
        for k, item in enumerate(filters):
            if not isinstance(item, _Filter):
                raise InputTypeError(f"filters[{k}] must be a Notch, RollOff or LeadLag; got "
                                     f"{type(item).__name__}")
        object.__setattr__(self, "filters", filters)
        blocks = [_canonical(*item.discrete(self.sample_time)) for item in filters]
        a, b, c, d = blocks[0]
        for a2, b2, c2, d2 in blocks[1:]:                   # y = F2(F1(u))
            n1, n2 = a.shape[0], a2.shape[0]
            a = np.block([[a, np.zeros((n1, n2))], [b2 @ c, a2]])
            b = np.vstack((b, b2 @ d))
            c = np.hstack((d2 @ c, c2))
            d = d2 @ d
        for name, value in zip("abcd", (a, b, c, d)):
            object.__setattr__(self, name, value)

    @property
    def order(self) -> int:
        """Number of states of the cascade."""
        return self.a.shape[0]

    def step(self, state: np.ndarray, u: float) -> tuple:
        """``(y, state_next)``: the filtered command and the filters' next state, for the
        command ``u`` at a sample.

        Parameters
        ----------
        state : ndarray, shape (order,)
            The filters' state at the sample.
        u : float
            The command entering the filters.
        """
        state = np.asarray(state, dtype=float)
        y = float((self.c @ state)[0] + self.d[0, 0] * u)
        return y, self.a @ state + self.b[:, 0] * u

    def response(self, frequencies) -> np.ndarray:
        """The cascade's complex response at ``frequencies`` (rad/s), discrete.

        Parameters
        ----------
        frequencies : array_like
            Frequencies, rad/s.
        """
        out = np.ones(np.shape(frequencies), dtype=complex)
        for item in self.filters:
            out = out * item.response(frequencies, self.sample_time)
        return out


def _canonical(num, den) -> tuple:
    """The controllable canonical form ``(A, B, C, D)`` of ``num(z) / den(z)`` (equal degree,
    ``den`` monic)."""
    n = den.size - 1
    a = np.zeros((n, n))
    a[0, :] = -den[1:]
    a[1:, :-1] = np.eye(n - 1)
    b = np.zeros((n, 1))
    b[0, 0] = 1.0
    d = np.array([[num[0]]])
    c = (num[1:] - num[0] * den[1:]).reshape(1, n)
    return a, b, c, d


def bounded(y: float, limit: float | None) -> float:
    """``y`` clipped to ``[-limit, limit]`` (as given when ``limit`` is None).

    Parameters
    ----------
    y : float
        A command.
    limit : float or None
        Its bound.
    """
    return y if limit is None else min(max(y, -limit), limit)


@dataclass(frozen=True, eq=False)
class _FilteredSession:
    inner: object
    cascade: FilterCascade
    limit: float | None
    state: np.ndarray

    def step(self, t, x):
        y, self.state[:] = self.cascade.step(self.state, float(self.inner.step(t, x)))
        return bounded(y, self.limit)

    def report(self):
        return self.inner.report()


@dataclass(frozen=True, eq=False, kw_only=True)
class Filtered(KeywordOnly):
    """A sampled law whose command passes through structural filters before the plant.

    Parameters
    ----------
    law : sampled controller
        A law run at a sample time: a :class:`~flexctl.sim.digital.ZeroOrderHold` of a
        state-feedback law (PD, LQR, ScheduledLQR, TrajectoryTracker, LaggedLQR) or an
        :class:`~controllers.Observed` law.
    filters : sequence of Notch, RollOff or LeadLag
        Applied in series to each command, discretised at the law's sample time
        (:class:`FilterCascade`).
    torque_limit : float, optional
        Bound on the filtered command, N m (the law's own bound acts before the filters).
        Default none.

    Notes
    -----
    An observed law's Kalman filter predicts with the law's own command, before the
    structural filters: the loop analysis (:meth:`loop_matrices`) models the same.
    """

    law: object
    filters: tuple
    torque_limit: float | None = None

    def __post_init__(self):
        step = getattr(self.law, "sample_time", None)
        if not callable(getattr(self.law, "start", None)) or step is None:
            raise InputTypeError("Filtered.law must be a sampled law (a ZeroOrderHold or an "
                                 "Observed law, with a sample_time); got "
                                 f"{type(self.law).__name__}")
        object.__setattr__(self, "cascade", FilterCascade(self.filters, float(step)))
        object.__setattr__(self, "filters", self.cascade.filters)
        if self.torque_limit is not None:
            object.__setattr__(self, "torque_limit", _positive("Filtered", "torque_limit",
                                                               self.torque_limit))

    @property
    def sample_time(self) -> float:
        """The law's sample time, s."""
        return float(self.law.sample_time)

    @property
    def measures(self) -> bool:
        """Whether the law reads sensors (then the run passes their readings)."""
        return bool(getattr(self.law, "measures", False))

    @property
    def sensors(self):
        """The sensors the law reads, or None."""
        return getattr(self.law, "sensors", None)

    def for_plant(self, model) -> "Filtered":
        """The same filters behind the law bound to plant ``model`` (where it has
        ``for_plant``).

        Parameters
        ----------
        model : flexctl.Model
            The plant the law runs on.
        """
        inner = self.law.for_plant(model) if callable(getattr(self.law, "for_plant", None)) \
            else self.law
        return Filtered(law=inner, filters=self.filters, torque_limit=self.torque_limit)

    def start(self, model, x0):
        """A session: the law's, its commands filtered (the filters start at rest).

        Parameters
        ----------
        model : flexctl.Model
            The plant of the run.
        x0 : ndarray, shape (n,)
            Initial plant state.
        """
        return _FilteredSession(self.law.start(model, x0), self.cascade, self.torque_limit,
                                np.zeros(self.cascade.order))

    def loop_matrices(self, model, spin_rate: float = 0.0):
        """The discrete loop ``F(z) L(z)`` broken at the plant input, as arrays
        (:class:`~controllers.feedback.observed_loop.LoopMatrices`): the law's sampled loop
        (the held plant under its state gain, or an observed law's loop as it flies) with the
        filters on its command.

        Parameters
        ----------
        model : flexctl.Model
            The plant, linearised about ``spin_rate``.
        spin_rate : float, optional
            Steady hub rate, rad/s. Default 0.

        Raises
        ------
        InputTypeError
            If the law has no linear loop (an NMPC, a motor's voltage).
        """
        from .observed_loop import LoopMatrices

        a, b, c, names = self._law_loop(model, spin_rate)
        cas = self.cascade
        n, m = a.shape[0], cas.order
        # the filter reads the law's command u = -(return) = -c w and drives the plant input
        a_loop = np.zeros((n + m, n + m))
        a_loop[:n, :n] = a
        a_loop[n:, :n] = -cas.b @ c          # filter state driven by the command -c w
        a_loop[n:, n:] = cas.a
        b_loop = np.vstack((b, np.zeros((m, 1))))
        # returned torque: minus the filtered command = -(C_f x_f + D_f (-c w))
        c_loop = np.hstack((cas.d[0, 0] * c, -cas.c))
        return LoopMatrices(a_loop, b_loop, c_loop, self.sample_time,
                            (*names, *(f"structural_filter_{k}" for k in range(m))))

    def _law_loop(self, model, spin_rate):
        """``(A, B, C, names)`` of the law's own sampled loop (return = C w)."""
        law = self.law
        if callable(getattr(law, "loop_matrices", None)):
            a, b, c, _, names = law.loop_matrices(model, spin_rate)
            return np.asarray(a), np.asarray(b), np.asarray(c), tuple(names)
        inner = getattr(law, "law", None)
        gain = getattr(inner, "plant_gain", None)
        if not callable(gain):
            raise InputTypeError("Filtered: the loop needs a law with a state gain (PD, LQR, "
                                 "ScheduledLQR, TrajectoryTracker, LaggedLQR) or an Observed "
                                 f"law; got {type(inner or law).__name__}")
        from ..design.controllable import held

        a, b = (np.asarray(v, dtype=float) for v in model.linear_matrices(spin_rate))
        phi, gam = held(a, b, self.sample_time)
        k = np.asarray(gain(model, spin_rate), dtype=float).reshape(1, -1)
        return phi, gam, k, tuple(model.state_names)
