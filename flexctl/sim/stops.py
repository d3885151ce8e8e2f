"""Why a run stops: the stopping conditions of :func:`flexctl.simulate` and their reasons.

A run stops early when the tip leaves the range of its model (the modal tip passes the beam
length for the small-deflection variants; the exact beam curls back on itself), when the mass
matrix turns singular (the consistent variant's effective hub inertia reaches zero), or when
the integrator fails. :class:`StopConditions` holds the conditions of one run, as events for
SciPy's ``solve_ivp`` and as a test of output samples for the compiled paths, and names the
physical reason of a stop.
"""

from __future__ import annotations

from enum import Enum

import numpy as np

from ..model import Model
from ..model.variant import EXACT_CURL, model_reach

__all__ = ["tip_rows", "reach_ratio", "StopReason", "StopConditions", "stiffness_reason", "model_reach",
           "SINGULAR_FRACTION", "EXACT_CURL"]

#: Integration stops as "singular" when the effective hub inertia falls below this fraction
#: of its value at rest (the exact singularity cannot be integrated up to).
SINGULAR_FRACTION = 1e-9


def reach_ratio(model: Model, q) -> np.ndarray:
    """Largest ``|phi_k(l_k)^T q_k| / reach_k`` over the appendages for modal coordinates
    ``q`` (N,) or (N, P): 1 where the model leaves its range.

    Parameters
    ----------
    model : Model
        Gives the tip rows ``phi_k(l_k)`` and the reach (:func:`model_reach`), m.
    q : ndarray, shape (N,) or (N, P)
        Modal coordinates, m, in the order of ``model.layout.modal``.

    Returns
    -------
    float or ndarray, shape (P,)
    """
    tips = model.tip_matrix @ q
    reach = model_reach(model).reshape((-1,) + (1,) * (np.ndim(tips) - 1))
    return np.max(np.abs(tips) / reach, axis=0)


def tip_rows(model: Model, layout) -> np.ndarray:
    """The linear tip deflection of each appendage as rows over the states of ``layout``,
    shape (K, n): ``tips = tip_rows @ y``.

    Parameters
    ----------
    model : Model
        The model of the run: one tip row phi_k(l_k) per appendage.
    layout : StateLayout
        The layout of the states ``y`` (the model's, with a controller block, or without the
        hub rotation); ``n`` its number of states.
    """
    return np.vstack([layout.embed(row) for row in model.tip_matrix])


def _worst_appendage(model: Model, q) -> str:
    """``" of appendage 'name'"`` for the appendage nearest its reach (empty for one beam)."""
    names = model.structure.names
    if len(names) == 1 and not names[0]:
        return ""
    k = int(np.argmax(np.abs(model.tip_matrix @ q) / model_reach(model)))
    return f" of appendage {names[k]!r}"


class StopReason(Enum):
    """Why a run ended; ``status`` is the ``SimulationResult.status`` it gives."""

    REACHED_END = "reached t_final"
    TIP_PAST_LENGTH = "the modal tip passed the beam length (small-deflection variants)"
    BEAM_CURLED = "the exact beam curled back on itself"
    SINGULAR_MASS = "the mass matrix turned singular"
    STATE_OVERFLOW = "the state overflowed"
    INTEGRATOR_FAILED = "the integrator failed"
    NON_FINITE_STATE = "the state became non-finite"
    NON_FINITE_TORQUE = "the hub torque became non-finite"

    @property
    def status(self) -> str:
        """``"ok"``, ``"singular"`` or ``"diverged"``."""
        if self is StopReason.REACHED_END:
            return "ok"
        return "singular" if self is StopReason.SINGULAR_MASS else "diverged"


def stiffness_reason(model: Model, spin: float) -> str:
    """Why the beam of ``model`` may have left its range at hub rate ``spin`` (rad/s).

    Parameters
    ----------
    model : Model
        The model of the run, its beam stiffness and first clamped frequency.
    spin : float
        Hub rate, rad/s (its magnitude is reported).
    """
    w1 = model.first_clamped_frequency
    try:
        lowest = np.linalg.eigvalsh(model.stiffness_matrix(spin))[0]
    except (OverflowError, ValueError, np.linalg.LinAlgError):
        # a runaway (e.g. a torque of 1e12 N m) spun the hub so fast its square overflows
        return (f"the hub rate reached {abs(spin):.4g} rad/s, whose square overflows the beam "
                f"stiffness (first clamped frequency {w1:.4g} rad/s)")
    if lowest < 0.0:
        if not model.variant.dynamic_stiffening:
            term = "M_ff"
            extra = " (the zero_order model drops dynamic stiffening; use first_order)"
        else:
            term, extra = "(M_ff - K_g)", ""
        return (f"at hub rate {abs(spin):.4g} rad/s, above the first clamped frequency "
                f"{w1:.4g} rad/s, the beam stiffness K_ff - theta_dot^2 {term} has lost positive "
                f"definiteness and centrifugal softening wins over bending stiffness{extra}")
    return ("the deflection left the small-deflection range of the model "
            f"(hub rate {abs(spin):.4g} rad/s, first clamped frequency {w1:.4g} rad/s)")


def softened(model: Model, spin: float) -> bool:
    """True when the beam stiffness at hub rate ``spin`` has lost positive definiteness (or
    the rate's square overflows).

    Parameters
    ----------
    model : Model
        The model of the run.
    spin : float
        Hub rate, rad/s.
    """
    if not np.isfinite(spin ** 2):
        return True
    with np.errstate(all="ignore"):
        return bool(np.linalg.eigvalsh(model.stiffness_matrix(spin))[0] < 0.0)


def singular_message(model: Model, t_end: float, state) -> str:
    """Why the consistent model's mass matrix turned singular at ``t_end`` (s) in ``state``.

    Its Schur complement is the effective hub inertia at rest (computed without cancellation,
    :func:`flexctl.model.matrices.condensed_hub_inertia`) plus ``q^T D q``: a real
    singularity of the model, reached when the second-order inertia cancels the first.

    Parameters
    ----------
    model : Model
        The consistent variant.
    t_end : float
        Time of the stop, s.
    state : array_like, shape (n,)
        Plant state there, in the order of ``model.layout``.
    """
    structure, layout = model.structure, model.layout
    j_eff = float(model.effective_hub_inertia(state))
    j_rest = float(model.effective_hub_inertia(layout.zeros()))
    q = layout.modal(np.asarray(state))
    ratio = float(np.max(np.abs(model.tip_matrix @ q) / model.lengths))
    point_mass = sum(m.mass for a in structure.appendages for m in a.masses)
    beam_mass = sum(a.beam.mass for a in structure.appendages)
    system = structure
    cause = (f"the point masses ({point_mass:.4g} kg, {point_mass / beam_mass:.3g} times the "
             "beam mass) make it large against the hub's own inertia"
             if point_mass > beam_mass else
             f"a light hub (J_h = {system.hub.inertia:.4g} kg m^2) loses all of it")
    return (f"mass matrix singular at t = {t_end:.6g} s: the effective hub inertia "
            f"J_0 + q^T D q - m_tf^T M_ff^-1 m_tf fell to {j_eff:.3g} kg m^2 from "
            f"{j_rest:.4g} kg m^2 at rest (J_0 = {model.matrices.J0:.4g} kg m^2) as the "
            f"second-order inertia q^T D q reached {j_eff - j_rest:.4g} kg m^2 at a tip "
            f"deflection of {100 * ratio:.3g} % of the length{_worst_appendage(model, q)}; in the "
            f"consistent model the deflection lowers the hub inertia, and {cause}; the exact "
            "variant's mass matrix stays positive definite (the documentation's theory page, "
            "section 4.5)")


class StopConditions:
    """The stopping conditions of one run of ``model``.

    Parameters
    ----------
    model : Model
        The model of the run: its tips, reach and variant.
    layout : StateLayout
        Layout of the integrated state: the model's own, with a controller block, or
        :meth:`~flexctl.model.layout.StateLayout.without_rotation` for a prescribed hub.
    singular : bool
        Watch the effective hub inertia (the consistent variant with a free hub rotation).

    Attributes
    ----------
    reach : ndarray, shape (K,)
        Largest ``|phi_k(l_k)^T q_k|`` of each appendage, m: its beam length
        (small-deflection variants) or :data:`EXACT_CURL` lengths (exact).
    j_floor : float
        Effective hub inertia at which the run stops as singular, kg m^2 (0 when not watched).
    """

    def __init__(self, model: Model, layout, singular: bool):
        self.model, self.layout = model, layout
        self.reach = model_reach(model)
        self.singular = bool(singular)
        # relative to the effective hub inertia at rest (computed without cancellation), not
        # to J_0, which heavy point masses dominate: with 3e4 kg at the tip a J_0-based floor
        # stopped runs at 1e-4 kg m^2 of a true 1.16
        self.j_floor = (SINGULAR_FRACTION * float(model.effective_hub_inertia(
            model.layout.zeros())) if model.variant.quadratic_inertia else 0.0)
        self._plant = slice(0, model.n_states)
        # each appendage's tip over the integrated states, divided by its reach: (K, n)
        self._scaled_tips = tip_rows(model, layout) / self.reach[:, None]

    def reach_ratio(self, y):
        """Largest ``|phi_k(l_k)^T q_k| / reach_k`` of integrated state(s) ``y``: 1 where
        the model leaves its range.

        Parameters
        ----------
        y : ndarray, shape (n,) or (n, P)
            Integrated state(s), in the order of :attr:`layout`.

        Returns
        -------
        float or ndarray, shape (P,)
        """
        return np.max(np.abs(self._scaled_tips @ y), axis=0)

    def events(self) -> list:
        """Terminal events for ``solve_ivp``: the tip first, then the singular mass."""

        def tip_event(t, y):
            return 1.0 - float(self.reach_ratio(y))
        tip_event.terminal = True
        events = [tip_event]
        if self.singular:

            def singular_event(t, y):
                return float(self.model.effective_hub_inertia(y[self._plant])) - self.j_floor
            singular_event.terminal = True
            events.append(singular_event)
        return events

    def reason_of_event(self, index: int) -> StopReason:
        """The stop of the ``index``-th event of :meth:`events`.

        Parameters
        ----------
        index : int
            0 for the tip event, 1 for the singular mass.
        """
        return self.geometric() if index == 0 else StopReason.SINGULAR_MASS

    def geometric(self) -> StopReason:
        """The stop of a run whose tip left the range of the model."""
        return (StopReason.BEAM_CURLED if self.model.variant.exact
                else StopReason.TIP_PAST_LENGTH)

    def first_bad(self, y_seg) -> int | None:
        """Index of the first output sample (columns of ``y_seg``) past a condition, or None.

        Parameters
        ----------
        y_seg : ndarray, shape (n, K)
            Integrated states at a segment's output times, in the order of :attr:`layout`.
        """
        bad = ~np.all(np.isfinite(y_seg), axis=0) | (self.reach_ratio(y_seg) >= 1.0)
        if self.singular:
            bad |= np.asarray(self.model.effective_hub_inertia(y_seg[self._plant])) \
                <= self.j_floor
        return int(np.argmax(bad)) if bad.any() else None

    def reason_of_sample(self, y) -> StopReason:
        """Which condition the first bad sample ``y`` met.

        Parameters
        ----------
        y : ndarray, shape (n,)
            The integrated state at that sample, in the order of :attr:`layout`.
        """
        if not np.all(np.isfinite(y)):
            return StopReason.NON_FINITE_STATE
        if self.singular and float(self.model.effective_hub_inertia(y[self._plant])) \
                <= self.j_floor:
            return StopReason.SINGULAR_MASS
        return self.geometric()

    def message(self, reason: StopReason, t_end: float, state) -> str:
        """The physical reason of a stop at ``t_end`` (s) in plant state ``state``.

        Parameters
        ----------
        reason : StopReason
            The stop; a reason other than the tip's, the beam's or the mass matrix's is named by
            its value.
        t_end : float
            Time of the stop, s.
        state : array_like, shape (n,)
            Plant state there, in the order of ``model.layout``.
        """
        model = self.model
        if reason is StopReason.BEAM_CURLED:
            where = _worst_appendage(model, model.layout.modal(np.asarray(state)))
            return (f"the beam{where} curled back on itself at t = {t_end:.6g} s (mean slope angle "
                    f"above {EXACT_CURL:g} rad): the load is beyond what a beam of "
                    f"{model.n_modes} modes can describe")
        if reason is StopReason.TIP_PAST_LENGTH:
            q = model.layout.modal(np.asarray(state))
            k = int(np.argmax(np.abs(model.tip_matrix @ q) / model.lengths))
            return (f"tip deflection{_worst_appendage(model, q)} passed the beam length "
                    f"{model.lengths[k]:g} m at t = {t_end:.6g} s: "
                    + stiffness_reason(model, float(model.layout.hub_rate(state))))
        if reason is StopReason.SINGULAR_MASS:
            return singular_message(model, t_end, state)
        return reason.value + f" at t = {t_end:.6g} s"
