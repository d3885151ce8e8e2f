"""Monte Carlo of a spatial scene's attitude loop: the design made once, flown on dispersed
structures and sensor noise.

:class:`SpatialLoopTask` flies the law a scene designed on its nominal structure (``scene.loop``:
quaternion feedback, LQR or LQG, with its sensors and attitude filter) on a structure whose
appendages' stiffness (Young's and shear moduli) and hub inertia are scaled, with the sensors'
noise drawn from another seed: the law and its filter are not redesigned for the dispersed
plant, as a flight computer's are not. A call returns the run's status and what an attitude
engineer reads off a slew (the pointing error at the end, the residual vibration, the peak
wheel speed and power, the torque used).

:func:`spatial_monte_carlo` draws the dispersions (uniform within the given spreads, seeded) and
runs the task at every draw through :func:`flexctl.app.sweep.sweep`: in this process, or on any
executor, ``dask.distributed``'s ``Client.get_executor()`` included (the task and the scene
pickle).
"""

from __future__ import annotations

import dataclasses
import time

import numpy as np

from ..model.checks import check_integer, check_real
from ..model.errors import InputTypeError
from .spatial_control import pointing_target
from .spatial_scene import SpatialScene
from .sweep import SweepResult, sweep

__all__ = ["SpatialLoopTask", "spatial_monte_carlo", "dispersed_structure"]


def dispersed_structure(structure, stiffness: float = 1.0, inertia: float = 1.0):
    """``structure`` with its appendages' Young's and shear moduli times ``stiffness`` and its
    hub inertia (and mass) times ``inertia``.

    Parameters
    ----------
    structure : SpatialStructure
        The nominal structure.
    stiffness : float, optional
        Factor of every appendage's moduli (> 0). Default 1.
    inertia : float, optional
        Factor of the hub's inertia tensor and mass (> 0). Default 1.

    Returns
    -------
    SpatialStructure
    """
    stiffness = check_real("dispersed_structure", "stiffness", stiffness, minimum=0.0,
                           strict=True, maximum=1e3)
    inertia = check_real("dispersed_structure", "inertia", inertia, minimum=0.0, strict=True,
                         maximum=1e3)
    hub = structure.hub
    hub = dataclasses.replace(hub, inertia=np.asarray(hub.inertia) * inertia,
                              **({"mass": hub.mass * inertia} if hub.mass else {}))
    appendages = tuple(dataclasses.replace(a, youngs_modulus=a.youngs_modulus * stiffness,
                                           shear_modulus=a.shear_modulus * stiffness)
                       for a in structure.appendages)
    return dataclasses.replace(structure, hub=hub, appendages=appendages)


@dataclasses.dataclass(frozen=True, eq=False)
class SpatialLoopTask:
    """Fly a spatial scene's designed loop on a dispersed structure (module description).

    Parameters
    ----------
    scene : SpatialScene
        A spatial scene with a ``[controller]`` (its law designed on the nominal structure).
    settle_window : float, optional
        The last seconds of the run over which the residual vibration is read, s. Default
        half the run.
    """

    scene: SpatialScene
    settle_window: float | None = None

    def __post_init__(self):
        if not isinstance(self.scene, SpatialScene) or self.scene.loop is None:
            raise InputTypeError("SpatialLoopTask.scene must be a spatial scene with a "
                                 "[controller]")
        if self.settle_window is not None:
            check_real("SpatialLoopTask", "settle_window", self.settle_window, minimum=0.0,
                       strict=True, maximum=self.scene.t_final)

    def __call__(self, stiffness: float = 1.0, inertia: float = 1.0, seed: int = 0) -> dict:
        """One run: the dispersed structure, the sensors' noise from ``seed``.

        Parameters
        ----------
        stiffness : float, optional
            Factor of the appendages' moduli. Default 1.
        inertia : float, optional
            Factor of the hub's inertia and mass. Default 1.
        seed : int, optional
            Seed of the sensors' noise. Default 0.

        Returns
        -------
        dict
            ``status``, ``pointing_error`` (rad, at the end), ``residual_vibration`` (m, the
            largest tip displacement over the settle window), ``peak_wheel_speed`` (rad/s) and
            ``peak_wheel_power`` (W) with wheels, ``torque_used`` (N m s, ``int |u|_1 dt``),
            ``wall_time_s``.
        """
        from ..sim.quaternions import error_angles
        from .spatial_report import run_spatial_scene

        scene = self.scene
        start = time.perf_counter()
        loop = scene.loop
        if loop.sensors is not None:
            loop = dataclasses.replace(loop, sensors=dataclasses.replace(
                loop.sensors, seed=check_integer("SpatialLoopTask", "seed", seed, minimum=0)))
        flown = dataclasses.replace(scene, structure=dispersed_structure(
            scene.structure, stiffness, inertia), loop=loop)
        result = run_spatial_scene(flown)
        window = self.settle_window or 0.5 * scene.t_final
        late = result.t >= result.t[-1] - window
        tips = np.array([np.linalg.norm(v, axis=0) for v in result.tips.values()])
        out = {"status": result.status,
               "pointing_error": float(np.linalg.norm(error_angles(
                   pointing_target(loop.law, result.t[-1]), result.states[0:4, -1]))),
               "residual_vibration": float(np.max(tips[:, late])),
               "torque_used": float(np.sum(np.abs(result.torque[:, :-1])
                                           * np.diff(result.t)))}
        if result.equations.cluster is not None:
            out["peak_wheel_speed"] = float(np.max(np.abs(result.wheel_speeds)))
            out["peak_wheel_power"] = float(np.max(result.wheel_power))
        out["wall_time_s"] = time.perf_counter() - start
        return out


def spatial_monte_carlo(scene: SpatialScene, samples: int, *, stiffness_spread: float = 0.1,
                        inertia_spread: float = 0.05, seed: int = 0, executor=None,
                        progress: bool = False) -> SweepResult:
    """A Monte Carlo of ``scene``'s loop: ``samples`` runs of :class:`SpatialLoopTask`, each
    with the appendages' stiffness and the hub inertia scaled by factors drawn uniformly from
    ``1 +- spread`` and its own sensor seed.

    Parameters
    ----------
    scene : SpatialScene
        A spatial scene with a ``[controller]``.
    samples : int
        Runs (1 to 100 000).
    stiffness_spread : float, optional
        Half-width of the stiffness factor's range, in [0, 0.9]. Default 0.1.
    inertia_spread : float, optional
        Half-width of the hub inertia factor's range, in [0, 0.9]. Default 0.05.
    seed : int, optional
        Seed of the draws. Default 0.
    executor : Executor-like or callable, optional
        Where the runs go (:func:`~flexctl.app.sweep.sweep`: a process pool, or
        ``dask.distributed.Client(...).get_executor()``). Default: here, in order.
    progress : bool, optional
        Show a progress bar. Default False.

    Returns
    -------
    SweepResult
        A row per run: ``stiffness``, ``inertia``, ``seed`` and the task's outputs.

    Examples
    --------
    >>> from flexctl import load_scene
    >>> scene = load_scene("examples/scenes/spatial-lqg-slew.toml",
    ...                    overrides={"simulation.t_final": 2.0, "model.modes": 1})
    >>> table = spatial_monte_carlo(scene, 2, seed=1)
    >>> len(table.rows), sorted(table.rows[0])[:3]
    (2, ['inertia', 'peak_wheel_power', 'peak_wheel_speed'])
    """
    task = SpatialLoopTask(scene)
    samples = check_integer("spatial_monte_carlo", "samples", samples, minimum=1,
                            maximum=100_000)
    spreads = {name: check_real("spatial_monte_carlo", name, value, minimum=0.0, maximum=0.9)
               for name, value in (("stiffness_spread", stiffness_spread),
                                   ("inertia_spread", inertia_spread))}
    seed = check_integer("spatial_monte_carlo", "seed", seed, minimum=0)
    rng = np.random.default_rng(seed)
    points = [{"stiffness": float(1.0 + spreads["stiffness_spread"] * rng.uniform(-1, 1)),
               "inertia": float(1.0 + spreads["inertia_spread"] * rng.uniform(-1, 1)),
               "seed": int(rng.integers(0, 2 ** 31 - 1))} for _ in range(samples)]
    return sweep(task, points, executor=executor, progress=progress,
                 description=f"{scene.name} Monte Carlo", seed=seed)
