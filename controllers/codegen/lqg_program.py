"""LQG with its estimator discretised at the sample time, as a CasADi step function.

The step is :class:`controllers.feedback.lqg_sampled.SampledLQG`'s: ``u_k = law(t_k, z_k)``, then
``z_{k+1} = Phi z_k + Gamma [u_k; y_k]``; its input is the readings ``y`` (hub angle and each
appendage's root moment), its memory the estimate ``z``.
"""

from __future__ import annotations

import numpy as np

from .program import ControllerProgram, ExportRefused, plant_output

__all__ = ["lqg_program"]


def lqg_program(lqg, plant, sample_time, x0) -> ControllerProgram:
    """The program of ``lqg`` on ``plant``, its estimator discretised at ``sample_time``.

    Parameters
    ----------
    lqg : LQG
        The continuous design (:class:`controllers.feedback.lqg.LQG`).
    plant : flexctl.Model
        The plant the law reads (its state order, sensors and actuator).
    sample_time : float or None
        Rate the estimator is discretised at, s (> 0); None is refused.
    x0 : array_like, shape (n,)
        Plant state at the start (the estimate's initial value is the LQG's own).

    Raises
    ------
    ExportRefused
        Without a ``sample_time``, or for a reference with no CasADi form.
    """
    import casadi as ca

    from controllers.feedback.lqg import measured_outputs
    from controllers.feedback.lqg_sampled import SampledLQG

    if sample_time is None:
        raise ExportRefused("export: LQG's estimator is continuous; give the sample_time (s) "
                            "to discretise it at")
    if not lqg.has_casadi_form:
        raise ExportRefused("export: the LQG's reference has no CasADi form")
    lqg = lqg.for_plant(plant)
    sampled = SampledLQG(lqg, sample_time)
    n_y = lqg.measurement_matrix.shape[0]
    t, y, z = ca.SX.sym("t"), ca.SX.sym("v", n_y), ca.SX.sym("m", lqg.n_states)
    u = lqg.casadi_torque(t, None, z)
    z_next = ca.mtimes(ca.DM(sampled.phi), z) + ca.mtimes(ca.DM(sampled.gamma),
                                                          ca.vertcat(u, y))
    step = ca.Function("step", [t, y, z], [u, z_next], ["t", "v", "m"], ["u", "m_next"])
    name, unit = plant_output(plant)
    return ControllerProgram(
        kind="lqg", step=step, recover=None, input_names=tuple(measured_outputs(plant)),
        input_kind="measurement", output_name=name, output_unit=unit,
        memory_init=np.asarray(lqg.initial_state(x0), dtype=float),
        sample_time=float(sample_time), measurement_matrix=np.asarray(lqg.measurement_matrix),
        description=(f"LQG on {lqg.n_modes} design modes, estimator discretised at "
                     f"{sample_time:g} s"),
        info={"design_modes": lqg.n_modes, "estimator_states": lqg.n_states})
