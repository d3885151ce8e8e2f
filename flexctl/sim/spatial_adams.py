"""Compiled Adams-Moulton steps on a spatial model's compiled right-hand side.

A spatial run integrated by CVODES pays CasADi's interface on every step (vector operations,
a callback for each evaluation, its linear solves): on the equations restricted to a plane
(:mod:`flexctl.sim.spatial_plane`), whose right-hand side is a few microseconds, that cost is
as large as the evaluations'. Here the compiled multistep template of the planar models
(:mod:`flexctl.sim.compiled_bdf`, ``bdf.c`` with ``family="adams"``: LSODE's Adams-Moulton
methods of orders 1 to 12, Newton's iterations on a Jacobian taken by forward differences
at each segment's start and where the iterations fail) calls the model's compiled
right-hand side through its address, driven by a torque of the segment form
``p[0:3] + p[3:6] t + p[6:9] sin(p[9] (p[10] + t))``
(:func:`~flexctl.sim.exponential.segment_torque`): the library holds the integrator and the
torque, not the model (0.22 s to compile for two panels on 4 modes), once for every
right-hand side of the same sizes, kept in the persistent cache.

:class:`CompiledAdams` has the interface of :class:`~flexctl.sim.spatial_run.SpatialSegments`
(``count``, ``build``, ``advance``, ``steps``, ``evaluations``, ``form``) for a torque with a
segment form; a line through many samples and a torque given as a Python function stay on
CVODES and SciPy.
"""

from __future__ import annotations

import threading

import numpy as np

from .compiled_bdf import STATUS, BdfRun, assembled
from .compile_cache import compiling_enabled, entry_point
from .exponential import SegmentFailed, segment_torque
from ..model.checks import check_integer, check_real
from ..model.errors import InputValueError

__all__ = ["CompiledAdams", "adams_library", "SEGMENT_NUMBERS"]

#: Numbers of a segment's torque handed to the library: the 11 of its form and its start, s.
SEGMENT_NUMBERS = 12

def adams_library(native, values):
    """``(external, pieces)``: the compiled Adams-Moulton integrator around ``native`` (a
    compiled right-hand side from the cache, ``(x, torque (3), numbers) -> x_t``, its
    structure's numbers ``values``) driven by a segment's torque, or None where it has no
    entry point or compiling is off.

    Parameters
    ----------
    native : casadi.Function
        The lifted right-hand side as loaded from the compile cache
        (:func:`~flexctl.sim.compile_cache.compiled`).
    values : ndarray
        Its numbers (the lifted constants).

    Returns
    -------
    tuple or None
    """
    import casadi as ca

    if not compiling_enabled():
        return None
    point = entry_point(native)
    if point is None:
        return None
    n = int(native.size1_in(0))
    t, y, c = ca.SX.sym("t"), ca.SX.sym("y", n), ca.SX.sym("c", SEGMENT_NUMBERS)
    torque = segment_torque(c[0:11], t - c[11])
    pieces = {"F": ca.Function("flexctl_bdf_f", [t, y, c], [torque]), "J": None,
              "f_values": np.asarray(values, dtype=float).ravel(), "j_values": np.zeros(0),
              "address": point[0], "keep": (native, point[1]),
              "defines": {"BDF_CORE": 1, "BDF_MOTION": 0, "BDF_NX": n, "BDF_NQ": n // 2,
                          "BDF_NPRE": 3, "BDF_CORE_ARG": native.sz_arg(),
                          "BDF_CORE_RES": native.sz_res(), "BDF_CORE_IW": native.sz_iw(),
                          "BDF_CORE_W": native.sz_w()}}
    return assembled(pieces, SEGMENT_NUMBERS, "adams",
                     f"the spatial Adams-Moulton integrator ({n} states)")


class CompiledAdams:
    """A spatial run's segments by compiled Adams-Moulton steps (LSODE's, orders 1 to 12,
    Newton's iterations), each segment from order 1, the step carried from segment to
    segment.

    Parameters
    ----------
    built : tuple
        The library, :func:`adams_library`.
    n_states : int
        States integrated (the right-hand side's).
    drive : callable
        The torque, with ``segment_form(a, b)`` (its 11 numbers on a segment).
    rtol, atol : float
        Tolerances of each step's local error (weighted RMS norm, as CVODES's).
    max_steps : int
        Most step attempts between two output times.
    h_first : float
        The first step tried, s.
    explain : callable, optional
        ``explain(a, b, x, wanted) -> str``: why the step budget ran out on a segment (asked
        in the thread that built this object only). Default: the budget alone is named.
    """

    def __init__(self, built, n_states: int, drive, rtol: float, atol: float,
                 max_steps: int, h_first: float, explain=None):
        owner = "CompiledAdams"
        if not callable(getattr(drive, "segment_form", None)):
            raise InputValueError(f"{owner} drive must have a segment_form(a, b); got "
                                  f"{type(drive).__name__}")
        external = built[0] if isinstance(built, tuple) and len(built) == 2 else None
        n_states = check_integer(owner, "n_states", n_states, minimum=1)
        if not hasattr(external, "nnz_in") or external.nnz_in(1) != n_states:
            raise InputValueError(f"{owner} built must be adams_library's (external, pieces) "
                                  f"for n_states = {n_states} states; got {built!r:.80}")
        rtol = check_real(owner, "rtol", rtol, minimum=0.0, strict=True, maximum=1.0)
        atol = check_real(owner, "atol", atol, minimum=0.0, strict=True)
        max_steps = check_integer(owner, "max_steps", max_steps, minimum=1)
        h_first = check_real(owner, "h_first", h_first, minimum=0.0, strict=True)
        self.drive, self.form, self.explain = drive, drive.segment_form, explain
        self.run = BdfRun.on_library(built, n_states, np.full(n_states, atol),
                                     np.zeros(SEGMENT_NUMBERS), rtol=rtol,
                                     max_steps=max_steps, h_first=h_first)
        self.numbers = self.run._run.args[5]        # the segment's torque, set per segment
        self.n_states, self.max_steps = n_states, max_steps
        self.steps = self.evaluations = 0
        self.creator = threading.get_ident()

    def count(self, pieces) -> int:
        """Integrators to build for ``pieces``: none (one library serves every segment).

        Parameters
        ----------
        pieces : list of tuple
            ``(a, b, wanted)`` each.
        """
        return 0

    def build(self, a: float, b: float, wanted) -> None:
        """Nothing to build (the interface of
        :class:`~flexctl.sim.spatial_run.SpatialSegments`).

        Parameters
        ----------
        a, b : float
            A segment's ends, s.
        wanted : array_like
            Its output times, s.
        """

    def advance(self, a: float, b: float, x, wanted) -> np.ndarray:
        """The states at ``wanted``, from ``x`` at ``a``.

        Parameters
        ----------
        a, b : float
            The segment's ends, s.
        x : ndarray, shape (n_states,)
            The state at ``a``.
        wanted : array_like
            Output times in ``(a, b]``, ascending, ending at ``b``, s.

        Returns
        -------
        ndarray, shape (n_states, len(wanted))
            NaN where the state left the finite numbers.

        Raises
        ------
        SegmentFailed
            When the steps cannot go on (the message says why).
        """
        run = self.run
        self.numbers[0:11] = np.asarray(self.form(a, b), dtype=float)
        self.numbers[11] = a
        try:
            states, _ = run(a, np.asarray(wanted, dtype=float), x)
        except RuntimeError as exc:
            return self._failed(a, b, x, wanted, str(exc))
        finally:
            self.steps += run.last_stats.get("steps", 0)
            self.evaluations += run.last_stats.get("evaluations", 0)
        return states

    def _failed(self, a, b, x, wanted, message: str) -> np.ndarray:
        if STATUS[3] in message:
            return np.full((self.n_states, len(wanted)), np.nan)
        if STATUS[1] in message:
            if self.explain is not None and threading.get_ident() == self.creator:
                raise SegmentFailed(self.explain(a, b, x, wanted))
            raise SegmentFailed(f"the Adams-Moulton steps took all of their {self.max_steps:g} "
                                f"steps between two output times in [{a:g}, {b:g}] s")
        raise SegmentFailed(f"the Adams-Moulton steps failed in [{a:g}, {b:g}] s: {message}")
