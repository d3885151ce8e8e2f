"""LQG run on a flight computer: its estimator discretised at a sample time.

:class:`~controllers.feedback.lqg.LQG` integrates its Kalman filter
``dz/dt = A z + B u + L (y - C z)``
continuously. Sampled every ``T`` seconds, with the torque ``u_k`` and the readings ``y_k`` held
over the sample (zero-order hold), the same filter is exactly

    u_k     = law(t_k, z_k)                       (LQG.torque: LQR on the estimate)
    z_{k+1} = Phi z_k + Gamma_u u_k + Gamma_y y_k

with ``Phi = exp((A - L C) T)`` and ``[Gamma_u, Gamma_y] = int_0^T exp((A - L C) s) ds [B, L]``:
the readings of sample ``k`` enter the command of sample ``k + 1``. :class:`SampledLQG` is this
law as a :class:`flexctl.sim.digital.SampledController`, the form :mod:`controllers.codegen`
writes as C.

Examples
--------
>>> import numpy as np, flexctl
>>> from controllers.feedback.lqg import NoiseLevels, design_lqg
>>> from controllers.feedback.lqr import LQRWeights
>>> from controllers.feedback.lqg_sampled import SampledLQG
>>> model = flexctl.build_model(flexctl.load_scene("hub-beam-mass").system, n_modes=2)
>>> lqg = design_lqg(model, LQRWeights(hub_angle=0.05, torque=5.0),
...                  NoiseLevels(angle=1e-4, root_moment=1e-3, torque=0.1))
>>> sampled = SampledLQG(lqg, sample_time=0.01)
>>> sampled.phi.shape, sampled.gamma.shape
((6, 6), (6, 3))
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
import scipy.linalg

from flexctl.model.checks import check_instance
from flexctl.sim.digital import check_sample_time
from flexctl.sim.drives import bound_to_plant

from .lqg import LQG

__all__ = ["SampledLQG", "discretised_estimator"]


def discretised_estimator(lqg: LQG, sample_time: float) -> tuple:
    """``(Phi, Gamma)`` of the module docstring: shapes (n_d, n_d) and (n_d, 1 + m), the
    columns of ``Gamma`` on ``[u, y_1..y_m]``.

    Parameters
    ----------
    lqg : LQG
        The continuous design (its ``A``, ``B``, ``C`` and Kalman gain ``L``).
    sample_time : float
        ``T``, s (> 0): the torque and the readings are held over it.
    """
    a_e = lqg.a - lqg.estimator_gain @ lqg.c
    inputs = np.hstack((lqg.b, lqg.estimator_gain))
    n, k = a_e.shape[0], inputs.shape[1]
    block = np.zeros((n + k, n + k))
    block[:n, :n], block[:n, n:] = a_e, inputs
    hold = scipy.linalg.expm(block * sample_time)
    return hold[:n, :n], hold[:n, n:]


@dataclass(frozen=True, eq=False)
class SampledLQG:
    """An :class:`~controllers.feedback.lqg.LQG` with its estimator discretised at ``sample_time``.

    Parameters
    ----------
    lqg : LQG
        The continuous design (gains, reference, saturation, motor line).
    sample_time : float
        Sample time the estimator is discretised at, s (> 0).

    Attributes
    ----------
    phi, gamma : ndarray
        The discretised estimator (:func:`discretised_estimator`).
    """

    lqg: LQG
    sample_time: float
    phi: np.ndarray = field(init=False, repr=False)
    gamma: np.ndarray = field(init=False, repr=False)

    def __post_init__(self):
        check_instance("sampled_lqg", "lqg", self.lqg, LQG)
        object.__setattr__(self, "sample_time", check_sample_time("SampledLQG", self.sample_time))
        phi, gamma = discretised_estimator(self.lqg, self.sample_time)
        phi.setflags(write=False)
        gamma.setflags(write=False)
        object.__setattr__(self, "phi", phi)
        object.__setattr__(self, "gamma", gamma)

    @property
    def breakpoints(self) -> tuple:
        """Times (s) where the reference is not smooth."""
        return self.lqg.breakpoints

    def start(self, model, x0) -> "SampledLQGSession":
        """A fresh session for a run of the plant ``model`` from ``x0``.

        Parameters
        ----------
        model : flexctl.Model
            The plant, whose sensors the LQG reads (its layout binds the law).
        x0 : array_like, shape (n,)
            Plant state at the start of the run (the initial estimate does not read it).
        """
        return SampledLQGSession(self, bound_to_plant(self.lqg, model), x0)


class SampledLQGSession:
    """One run of a :class:`SampledLQG`: the estimate ``z`` between samples.

    Parameters
    ----------
    owner : SampledLQG
        The sampled controller run (its discretised estimator and sample time).
    lqg : LQG
        Its continuous design, bound to the run's plant (:meth:`LQG.for_plant
        <controllers.feedback.lqg.LQG.for_plant>`).
    x0 : array_like, shape (n,)
        Plant state at the start (not read by the estimate, which starts from the LQG's
        initial estimate).
    """

    def __init__(self, owner: SampledLQG, lqg: LQG, x0):
        self.owner, self.lqg = owner, lqg
        self.z = lqg.initial_state(x0)
        self.samples = 0

    def step(self, t: float, x) -> float:
        """Torque (N m) to hold from ``t``, given the plant state ``x``.

        Parameters
        ----------
        t : float
            Sample time ``t_k``, s.
        x : array_like, shape (n,)
            Plant state at ``t``, read through the LQG's sensors (``lqg.measure``).
        """
        y = self.lqg.measure(t, x)
        return self.step_readings(t, y)

    def step_readings(self, t: float, y) -> float:
        """Torque (N m) to hold from ``t``, given the readings ``y``.

        Parameters
        ----------
        t : float
            Sample time ``t_k``, s.
        y : array_like, shape (m,)
            Readings ``[theta, root_moment, ...]`` at ``t`` (rad, then N m for each
            appendage's root moment).
        """
        u = float(self.lqg.torque(t, None, self.z))
        self.z = self.owner.phi @ self.z + self.owner.gamma @ np.concatenate(([u], y))
        self.samples += 1
        return u

    def report(self) -> dict:
        """Samples taken."""
        return {"samples": self.samples, "estimator": "discretised"}
