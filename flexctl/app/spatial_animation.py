"""A spatial run as an animation: the structure turning and bending, drawn in 3-D (GIF).

Each frame draws, in the inertial frame, the hub's axes and every appendage's centreline on the
nodes of its quadrature (:meth:`flexctl.model.spatial_rod.Rod.motion`), the root points and
the point masses, from the run's states. Deflections of millimetres on rods of metres are
invisible at scale, so the centrelines' departure from the straight rods moving with the hub
is multiplied by ``exaggeration`` (by default so that the largest reaches a tenth of the
longest rod), and the factor is written in the title. The run's time is in the title too.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from ..model.checks import check_integer, check_real
from ..model.errors import InputValueError
from ..model.spatial_rod import Rod, rod_rule
from ..sim.atomic_files import atomic_file
from ..sim.quaternions import rotation_matrix
from ..sim.spatial_run import SpatialResult

__all__ = ["centrelines", "animate_spatial", "ANIMATION", "MAX_FRAMES"]

#: The file name a run's animation takes beside its other files (``flexctl run --animate``).
ANIMATION = "animation.gif"
#: Most frames of an animation (a GIF of more is slow to write and to open).
MAX_FRAMES = 600
#: Largest drawn deflection of the default exaggeration, relative to the longest rod.
DRAWN_DEFLECTION = 0.1


def centrelines(result: SpatialResult) -> list:
    """Every appendage's centreline at every output time, hub frame.

    Parameters
    ----------
    result : SpatialResult
        A spatial run.

    Returns
    -------
    list of ndarray, shape (P, 3, M_k)
        Per appendage: the root, the quadrature's nodes and the tip (``M_k`` points,
        ascending arc length), m, at each of the ``P`` output times.
    """
    import casadi as ca

    structure, layout = result.structure, result.layout
    out = []
    for k, appendage in enumerate(structure.appendages):
        n_modes = layout.counts[k]
        rod = Rod(appendage, rod_rule(appendage, structure.hub, n_modes), n_modes,
                  appendage.root_point(structure.hub))
        eta = ca.SX.sym("eta", 3 * n_modes)
        motion = rod.motion(eta, ca.SX.zeros(3 * n_modes))
        nodes = len(rod.rule.weights)
        line = ca.horzcat(ca.DM(rod.root), motion["points"][:, :nodes], motion["tip"])
        function = ca.Function("centreline", [eta], [line]).map(max(result.t.size, 1))
        first = layout.n_coordinates - layout.n_elastic + layout.block(k).start
        values = function(result.states[first:first + 3 * n_modes]).full()
        out.append(values.reshape(3, result.t.size, nodes + 2).transpose(1, 0, 2)
                   if result.t.size else np.zeros((0, 3, nodes + 2)))
    return out


def _straight(result: SpatialResult, lines: list) -> list:
    """The undeformed rods at the centrelines' arc lengths (the nodes' distance along each
    rod from its root), hub frame, shape (3, M_k) each."""
    out = []
    for appendage, line, n_modes in zip(result.structure.appendages, lines,
                                        result.layout.counts):
        root = np.asarray(appendage.root_point(result.structure.hub), dtype=float)
        arc = np.concatenate([[0.0], np.asarray(
            rod_rule(appendage, result.structure.hub, n_modes).nodes, dtype=float),
            [appendage.length]])
        out.append(root[:, None] + np.asarray(appendage.direction, dtype=float)[:, None]
                   * arc[None, :])
    return out


def animate_spatial(result: SpatialResult, path, *, frames: int = 120, fps: float = 20.0,
                    exaggeration: float | None = None, title: str = "") -> Path:
    """Write a GIF of ``result``: the structure turning and bending (written whole or not at
    all).

    Parameters
    ----------
    result : SpatialResult
        A spatial run with at least two output times.
    path : str or path-like
        The GIF to write; its folder must exist.
    frames : int, optional
        Frames, evenly spread over the run's output times (2 to :data:`MAX_FRAMES`; at most
        the output times). Default 120.
    fps : float, optional
        Frames per second of the GIF, in (0, 100]. Default 20.
    exaggeration : float, optional
        Factor on the deflections drawn, >= 1. Default: a tenth of the longest rod over the
        largest deflection (at least 1).
    title : str, optional
        Shown above the time. Default none.

    Returns
    -------
    pathlib.Path
        ``path``.
    """
    import matplotlib.pyplot as plt
    from PIL import Image

    if not isinstance(result, SpatialResult):
        raise InputValueError(f"animate_spatial: result must be a SpatialResult; got "
                              f"{type(result).__name__}")
    if result.t.size < 2:
        raise InputValueError(f"animate_spatial: result must have at least 2 output times; "
                              f"got {result.t.size}")
    frames = check_integer("animate_spatial", "frames", frames, minimum=2, maximum=MAX_FRAMES)
    fps = check_real("animate_spatial", "fps", fps, minimum=0.0, strict=True, maximum=100.0)
    lines = centrelines(result)
    straight = _straight(result, lines)
    largest = max(float(np.max(np.abs(line - rest[None]))) for line, rest in zip(lines, straight))
    reach = max(float(np.linalg.norm(np.asarray(a.root_point(result.structure.hub)))) + a.length
                for a in result.structure.appendages)
    longest = max(a.length for a in result.structure.appendages)
    if exaggeration is None:
        exaggeration = max(1.0, DRAWN_DEFLECTION * longest / largest) if largest > 0 else 1.0
    exaggeration = check_real("animate_spatial", "exaggeration", exaggeration, minimum=1.0,
                              maximum=1e12)
    picks = np.unique(np.linspace(0, result.t.size - 1, min(frames, result.t.size)).round()
                      .astype(int))
    positions = result.hub_position
    fig = plt.figure(figsize=(5.5, 5.0))
    axes = fig.add_subplot(projection="3d")
    limit = 1.1 * reach
    for bound in (axes.set_xlim, axes.set_ylim, axes.set_zlim):
        bound(-limit, limit)
    axes.set_box_aspect((1, 1, 1), zoom=1.5)
    fig.subplots_adjust(left=0.0, right=1.0, bottom=0.0, top=0.9)
    axes.set_axis_off()             # the inertial axes drawn as a faint triad instead
    for axis in np.eye(3):
        axes.plot(*zip(np.zeros(3), 0.4 * reach * axis), color="0.85", lw=0.8)
    triad = [axes.plot([], [], [], color=c, lw=1.0)[0]
             for c in ("tab:red", "tab:green", "tab:blue")]
    ghosts = [axes.plot([], [], [], color="0.75", lw=1.0, ls="--")[0] for _ in lines]
    rods = [axes.plot([], [], [], color="tab:orange", lw=2.0)[0] for _ in lines]
    hub = axes.plot([], [], [], "s", color="0.3", markersize=8)[0]
    heading = fig.suptitle("", fontsize=9)

    def draw(k: int):
        rotation = rotation_matrix(result.quaternion[:, k])
        centre = np.zeros(3) if positions is None else positions[:, k]
        hub.set_data_3d([centre[0]], [centre[1]], [centre[2]])
        for artist, axis in zip(triad, np.eye(3)):
            artist.set_data_3d(*zip(centre, centre + rotation @ (0.4 * reach * axis)))
        for ghost, rod, line, rest in zip(ghosts, rods, lines, straight):
            ghost.set_data_3d(*(centre[:, None] + rotation @ rest))
            rod.set_data_3d(*(centre[:, None] + rotation @ (rest + exaggeration
                                                              * (line[k] - rest))))
        heading.set_text(f"{title + chr(10) if title else ''}t = {result.t[k]:.2f} s, "
                         f"deflections x {exaggeration:.3g}")
        fig.canvas.draw()
        return Image.fromarray(np.asarray(fig.canvas.buffer_rgba())[..., :3]).convert(
            "P", palette=Image.Palette.ADAPTIVE)

    target = Path(path)
    try:
        images = [draw(k) for k in picks]
        with atomic_file(target) as partial:
            images[0].save(partial, format="GIF", save_all=True, append_images=images[1:],
                           duration=round(1000.0 / fps), loop=0)
    finally:
        plt.close(fig)
    return target
