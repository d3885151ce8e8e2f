"""The state layout: the one owner of the names and slices of a state vector.

Every module that reads or builds a state asks a :class:`StateLayout` where its blocks are
(hub angle and rate, each appendage's modal coordinates and rates, hub translation, further
first-order blocks such as actuator or controller states) instead of slicing by index
arithmetic.

Notes
-----
A layout describes the state of a mechanical system with generalized coordinates and their
rates, followed by first-order blocks, in this order::

    x = [theta, hub_x, hub_y, q_(a,1) .. q_(a,N_a), q_(b,1) .. q_(b,N_b), ...,     coordinates
         theta_dot, hub_x_dot, hub_y_dot, q_(a,1)_dot .. q_(b,N_b)_dot, ...,       their rates
         <extra block 1>, <extra block 2>, ...]                                    first order

``hub_x, hub_y`` (m) are present for a free-floating hub only. The modal coordinates of all
appendages form one contiguous block (:attr:`StateLayout.q`), appendage after appendage in
the order given; a single appendage whose name is ``""`` has unprefixed names (``q1``), any
other appendage's names carry its name (``wing_a.q1``). ``theta`` may be absent
(:meth:`StateLayout.without_rotation`: the beam states integrated under a prescribed hub
rotation). Every accessor works on numpy arrays of shape ``(n,)`` or ``(n, P)`` (the first
axis is the state) and on CasADi column vectors.

Examples
--------
>>> layout = StateLayout.single(2)
>>> layout.names
('theta', 'q1', 'q2', 'theta_dot', 'q1_dot', 'q2_dot')
>>> layout.q, layout.theta_dot
(slice(1, 3, None), 3)
>>> two = StateLayout(appendages=(("wing_a", 2), ("wing_b", 1)), free_hub=True)
>>> two.names[:6]
('theta', 'hub_x', 'hub_y', 'wing_a.q1', 'wing_a.q2', 'wing_b.q1')
>>> two.modal_slice("wing_b"), two.n_states
(slice(5, 6, None), 12)
"""

from __future__ import annotations

import re
from dataclasses import dataclass, field
from functools import lru_cache

import numpy as np

from .checks import check_integer
from .errors import InputTypeError, InputValueError

__all__ = ["StateLayout"]


def _is_symbolic(x) -> bool:
    return type(x).__module__.startswith("casadi")


#: Most modes one appendage may carry (as :func:`flexctl.build_model`).
MAX_MODES = 200
_NAME = re.compile(r"[A-Za-z_][A-Za-z0-9_]*\Z")


def _checked_appendages(appendages) -> tuple:
    """``(name, n_modes)`` pairs: names unique identifiers (or one unnamed ``""``), counts
    from 1 to :data:`MAX_MODES`."""
    if not isinstance(appendages, (tuple, list)) or not appendages:
        raise InputValueError("StateLayout.appendages must name at least one appendage as "
                              f"(name, n_modes) pairs; got {appendages!r}")
    checked = []
    for entry in appendages:
        if not isinstance(entry, (tuple, list)) or len(entry) != 2 \
                or not isinstance(entry[0], str):
            raise InputTypeError("StateLayout.appendages must hold (name, n_modes) pairs; "
                                 f"got {entry!r}")
        name, modes = entry
        if not (name == "" and len(appendages) == 1) and not _NAME.match(name):
            raise InputValueError("StateLayout.appendages names must be identifiers (letters, "
                                  "digits, underscores; '' only for a single appendage); got "
                                  f"{name!r}")
        if name in dict(checked):
            raise InputValueError(f"StateLayout.appendages names must be unique; got {name!r} "
                                  "twice")
        checked.append((name, check_integer("StateLayout", "n_modes", modes, minimum=1,
                                            maximum=MAX_MODES)))
    return tuple(checked)


def _checked_extra(extra) -> tuple:
    """``(name, labels)`` pairs of the first-order blocks, names unique."""
    if not isinstance(extra, (tuple, list)):
        raise InputTypeError(f"StateLayout.extra must be (name, labels) pairs; got {extra!r}")
    checked = []
    for entry in extra:
        if not isinstance(entry, (tuple, list)) or len(entry) != 2 \
                or not isinstance(entry[0], str) or not isinstance(entry[1], (tuple, list)) \
                or not all(isinstance(label, str) for label in entry[1]):
            raise InputTypeError("StateLayout.extra must hold (name, labels) pairs of strings; "
                                 f"got {entry!r}")
        if entry[0] in dict(checked):
            raise InputValueError(f"StateLayout block {entry[0]!r} exists already")
        checked.append((entry[0], tuple(entry[1])))
    return tuple(checked)


def _block_array(value, size: int) -> np.ndarray:
    """A block's value as shape ``(size,)`` or ``(size, P)``: a block of one state may be a
    number or one value per column, shape ``(P,)``."""
    v = np.asarray(value, dtype=float)
    if size == 1 and v.ndim <= 1 and v.size:
        return v.reshape(1) if v.size == 1 else v.reshape(1, -1)
    if v.shape[:1] != (size,) or v.ndim > 2:
        raise InputValueError(f"a state block of {size} entries must have shape ({size},) or "
                              f"({size}, P); got {v.shape}")
    return v


@dataclass(frozen=True)
class StateLayout:
    """Names and slices of every block of a state vector (see the module Notes for the order).

    Parameters
    ----------
    appendages : tuple of (str, int)
        Each appendage's name and its number of modes, in state order. A single appendage
        named ``""`` gives unprefixed names.
    free_hub : bool
        The hub translates in the plane: coordinates ``hub_x, hub_y`` (m) follow ``theta``.
    rotation : bool
        ``theta`` and ``theta_dot`` are states (False: the hub rotation is prescribed).
    extra : tuple of (str, tuple of str)
        First-order blocks after the mechanical states: each block's name and its state names.
    """

    appendages: tuple = (("", 4),)
    free_hub: bool = False
    rotation: bool = True
    extra: tuple = ()
    _index: dict = field(init=False, repr=False, compare=False)

    def __post_init__(self):
        object.__setattr__(self, "appendages", _checked_appendages(self.appendages))
        for name in ("free_hub", "rotation"):
            if not isinstance(getattr(self, name), (bool, np.bool_)):
                raise InputTypeError(f"StateLayout.{name} must be True or False; got "
                                     f"{getattr(self, name)!r}")
            object.__setattr__(self, name, bool(getattr(self, name)))
        object.__setattr__(self, "extra", _checked_extra(self.extra))
        object.__setattr__(self, "_index", self._blocks())
        if len(set(self.names)) != len(self.names):
            raise InputValueError(f"StateLayout state names must be unique; got {self.names}")

    @classmethod
    def single(cls, n_modes: int) -> "StateLayout":
        """The layout of one unnamed appendage of ``n_modes`` modes on a pinned hub.

        Parameters
        ----------
        n_modes : int
            Modes of the beam, ``N`` (>= 1): the state has ``2 N + 2`` entries.
        """
        return cls(appendages=(("", n_modes),))

    # ------------------------------------------------------------------ construction
    def _blocks(self) -> dict:
        """``{block name: slice}`` for every block, and the state names."""
        coords = (["theta"] if self.rotation else []) + (["hub_x", "hub_y"] if self.free_hub
                                                         else [])
        modal = {}
        for name, modes in self.appendages:
            prefix = f"{name}." if name else ""
            modal[name] = (len(coords), len(coords) + modes)
            coords += [f"{prefix}q{i}" for i in range(1, modes + 1)]
        n_c = len(coords)
        names = coords + [f"{c}_dot" for c in coords]
        index = {"names": tuple(names), "n_coordinates": n_c, "modal": modal}
        start = len(names)
        for name, labels in self.extra:
            index.setdefault("extra", {})[name] = slice(start, start + len(labels))
            start += len(labels)
            names += list(labels)
        index["names"] = tuple(names)
        return index

    def with_block(self, name: str, labels) -> "StateLayout":
        """This layout with a first-order block ``name`` of states ``labels`` appended.

        Parameters
        ----------
        name : str
            Name of the block (:meth:`block`), not yet among the layout's blocks.
        labels : sequence of str
            Names of its states, in order, unique among the layout's state names.
        """
        return StateLayout(appendages=self.appendages, free_hub=self.free_hub,
                           rotation=self.rotation,
                           extra=self.extra + ((name, tuple(labels)),))

    def without_rotation(self) -> "StateLayout":
        """The mechanical states left when the hub rotation is prescribed (no extra blocks)."""
        return StateLayout(appendages=self.appendages, free_hub=self.free_hub, rotation=False)

    def with_modes(self, n_modes) -> "StateLayout":
        """The same blocks on other mode counts (a design model on fewer modes).

        Parameters
        ----------
        n_modes : int or sequence of int
            Modes of every appendage, or of each appendage in state order.
        """
        counts = (n_modes,) * len(self.appendages) if np.ndim(n_modes) == 0 else tuple(n_modes)
        if len(counts) != len(self.appendages):
            raise InputValueError(f"n_modes must be one count or {len(self.appendages)}; got "
                                  f"{n_modes!r}")
        return StateLayout(appendages=tuple((name, m) for (name, _), m
                                            in zip(self.appendages, counts)),
                           free_hub=self.free_hub, rotation=self.rotation, extra=self.extra)

    # ------------------------------------------------------------------ sizes and names
    @property
    def names(self) -> tuple:
        """State names in order."""
        return self._index["names"]

    @property
    def n_states(self) -> int:
        """Length of the state vector."""
        return len(self.names)

    @property
    def n_coordinates(self) -> int:
        """Number of generalized coordinates (hub angle, translation, modal coordinates)."""
        return self._index["n_coordinates"]

    @property
    def n_mechanical(self) -> int:
        """Coordinates and their rates: ``2 n_coordinates``."""
        return 2 * self.n_coordinates

    @property
    def n_modes(self) -> int:
        """Modal coordinates of all appendages together."""
        return sum(modes for _, modes in self.appendages)

    @property
    def appendage_names(self) -> tuple:
        """Appendage names in state order."""
        return tuple(name for name, _ in self.appendages)

    # ------------------------------------------------------------------ indices and slices
    def _require_rotation(self):
        if not self.rotation:
            raise InputValueError("this state layout has no hub rotation (prescribed hub)")

    @property
    def theta(self) -> int:
        """Index of the hub angle, rad."""
        self._require_rotation()
        return 0

    @property
    def theta_dot(self) -> int:
        """Index of the hub rate, rad/s."""
        self._require_rotation()
        return self.n_coordinates

    @property
    def coordinates(self) -> slice:
        """The generalized coordinates."""
        return slice(0, self.n_coordinates)

    @property
    def velocities(self) -> slice:
        """The rates of the generalized coordinates."""
        return slice(self.n_coordinates, self.n_mechanical)

    @property
    def mechanical(self) -> slice:
        """Coordinates and rates: the states of the structure."""
        return slice(0, self.n_mechanical)

    @property
    def hub_position(self) -> slice | None:
        """``hub_x, hub_y`` (m) for a free hub; ``None`` for a pinned one."""
        if not self.free_hub:
            return None
        start = 1 if self.rotation else 0
        return slice(start, start + 2)

    @property
    def hub_velocity(self) -> slice | None:
        """``hub_x_dot, hub_y_dot`` (m/s) for a free hub; ``None`` for a pinned one."""
        pos = self.hub_position
        return None if pos is None else slice(pos.start + self.n_coordinates,
                                              pos.stop + self.n_coordinates)

    @property
    def q(self) -> slice:
        """Modal coordinates of every appendage, m."""
        lo = self._index["modal"][self.appendages[0][0]][0]
        return slice(lo, lo + self.n_modes)

    @property
    def q_dot(self) -> slice:
        """Modal rates of every appendage, m/s."""
        q = self.q
        return slice(q.start + self.n_coordinates, q.stop + self.n_coordinates)

    def modal_slice(self, appendage: str = "") -> slice:
        """Modal coordinates of one appendage, as a slice of the state.

        Parameters
        ----------
        appendage : str, optional
            The appendage's name; ``""`` (default) for a single unnamed one.
        """
        if not isinstance(appendage, str) or appendage not in self._index["modal"]:
            raise InputValueError(f"appendage must be one of {list(self.appendage_names)}; "
                                  f"got {appendage!r}")
        return slice(*self._index["modal"][appendage])

    def modal_rate_slice(self, appendage: str = "") -> slice:
        """Modal rates of one appendage, as a slice of the state.

        Parameters
        ----------
        appendage : str, optional
            The appendage's name; ``""`` (default) for a single unnamed one.
        """
        s = self.modal_slice(appendage)
        return slice(s.start + self.n_coordinates, s.stop + self.n_coordinates)

    def block(self, name: str) -> slice:
        """A first-order block appended by :meth:`with_block`, as a slice of the state.

        Parameters
        ----------
        name : str
            The block's name (e.g. ``"actuator"``, ``"controller"``).
        """
        blocks = self._index.get("extra", {})
        if not isinstance(name, str) or name not in blocks:
            raise InputValueError(f"state block must be one of {list(blocks)}; got {name!r}")
        return blocks[name]

    @property
    def beam(self) -> np.ndarray:
        """Indices of the states integrated under a prescribed hub rotation (every state but
        ``theta`` and ``theta_dot``), in :meth:`without_rotation` order."""
        keep = np.ones(self.n_mechanical, dtype=bool)
        if self.rotation:
            keep[[self.theta, self.theta_dot]] = False
        return np.flatnonzero(keep)

    def projection(self, other: "StateLayout") -> np.ndarray:
        """Indices of this layout's states that form the state of ``other`` (a layout of the
        same blocks on fewer modes, e.g. a design model): each appendage's first modes.
        Read-only (kept for the next call: a sampled law asks at every sample).

        Parameters
        ----------
        other : StateLayout
            A layout of the same appendages and hub, with at most this one's modes on each
            appendage.

        Returns
        -------
        ndarray of int, shape (other.n_mechanical,)
            ``x[indices]`` is the state of ``other`` (its mechanical states).
        """
        if not isinstance(other, StateLayout):
            raise InputTypeError(f"other must be a StateLayout; got {type(other).__name__}")
        return _projection(self, other)

    def _projection(self, other: "StateLayout") -> np.ndarray:
        if other.appendage_names != self.appendage_names or other.free_hub != self.free_hub \
                or other.rotation != self.rotation:
            raise InputValueError("the layouts must have the same appendages and hub")
        rows = []
        for part in ("coordinates", "velocities"):
            offset = 0 if part == "coordinates" else self.n_coordinates
            if self.rotation:
                rows.append(offset)
            if self.free_hub:
                rows += [offset + k for k in range(self.hub_position.start,
                                                   self.hub_position.stop)]
            for name, modes in other.appendages:
                start = self.modal_slice(name).start
                if modes > dict(self.appendages)[name]:
                    raise InputValueError(f"appendage {name!r} has {dict(self.appendages)[name]}"
                                          f" modes here; cannot give {modes}")
                rows += [offset + start + k for k in range(modes)]
        rows = np.array(rows, dtype=int)
        rows.setflags(write=False)
        return rows

    # ------------------------------------------------------------------ accessors
    def hub_angle(self, x):
        """Hub angle(s), rad.

        Parameters
        ----------
        x : ndarray, shape (n,) or (n, P), or CasADi column
            State(s) in this layout (with the hub rotation).
        """
        return x[self.theta]

    def hub_rate(self, x):
        """Hub rate(s), rad/s.

        Parameters
        ----------
        x : ndarray, shape (n,) or (n, P), or CasADi column
            State(s) in this layout (with the hub rotation).
        """
        return x[self.theta_dot]

    def modal(self, x, appendage: str | None = None):
        """Modal coordinates (of every appendage, or of one), m.

        Parameters
        ----------
        x : ndarray, shape (n,) or (n, P), or CasADi column
            State(s) in this layout.
        appendage : str, optional
            An appendage's name (``""`` for a single unnamed one); default every appendage.
        """
        return x[self.q if appendage is None else self.modal_slice(appendage)]

    def modal_rates(self, x, appendage: str | None = None):
        """Modal rates (of every appendage, or of one), m/s.

        Parameters
        ----------
        x : ndarray, shape (n,) or (n, P), or CasADi column
            State(s) in this layout.
        appendage : str, optional
            An appendage's name (``""`` for a single unnamed one); default every appendage.
        """
        return x[self.q_dot if appendage is None else self.modal_rate_slice(appendage)]

    def split(self, x):
        """``theta, q, theta_dot, q_dot`` of a state (pinned hub, rotation included).

        Parameters
        ----------
        x : ndarray, shape (n,) or (n, P), or CasADi column
            State(s) in this layout.
        """
        return x[self.theta], x[self.q], x[self.theta_dot], x[self.q_dot]

    def embed(self, row, block: str = "q", size: int | None = None) -> np.ndarray:
        """A row vector that reads ``row`` against one block of the state: e.g. the tip
        deflection ``phi(l)^T q`` as a map of the whole state.

        Parameters
        ----------
        row : float or array_like, shape (k,)
            Entries for the block's ``k`` states; a single number fills every one.
        block : str, optional
            ``"q"`` (default), ``"q_dot"``, ``"theta"``, ``"theta_dot"``, ``"coordinates"``,
            ``"velocities"``, an appendage's ``"<name>.q"`` or ``"<name>.q_dot"``, or the name of
            a first-order block (:meth:`with_block`).
        size : int, optional
            Length of the row; default :attr:`n_states`.
        """
        out = np.zeros(self.n_states if size is None else int(size))
        target = self._named_slice(block)
        row = np.asarray(row, dtype=float)
        if row.size != 1 and row.shape != out[target].shape:
            raise InputValueError(f"a row for state block {block!r} must have shape "
                                  f"{out[target].shape}; got {row.shape}")
        out[target] = row
        return out

    def _named_slice(self, block: str):
        if block in ("q", "q_dot", "theta", "theta_dot", "coordinates", "velocities"):
            return getattr(self, block)
        if block.endswith(".q_dot"):
            return self.modal_rate_slice(block[:-6])
        if block.endswith(".q"):
            return self.modal_slice(block[:-2])
        return self.block(block)

    def join(self, *, theta=None, q=None, theta_dot=None, q_dot=None, hub_position=None,
             hub_velocity=None, **blocks):
        """A state from its blocks (missing blocks are zero).

        Each block is a number or an array whose first axis has the block's size; with arrays
        of shape ``(k, P)`` the result has shape ``(n, P)``. CasADi symbols give a CasADi
        column (``vertcat``).

        Parameters
        ----------
        theta : float or array_like, shape (P,), optional
            Hub angle, rad (read when the layout has the hub rotation).
        q : array_like, shape (N,) or (N, P), optional
            Modal coordinates of every appendage, m.
        theta_dot : float or array_like, shape (P,), optional
            Hub rate, rad/s (read when the layout has the hub rotation).
        q_dot : array_like, shape (N,) or (N, P), optional
            Modal rates of every appendage, m/s.
        hub_position : array_like, shape (2,) or (2, P), optional
            ``hub_x, hub_y`` of a free hub, m (read for a free hub only).
        hub_velocity : array_like, shape (2,) or (2, P), optional
            ``hub_x_dot, hub_y_dot`` of a free hub, m/s (read for a free hub only).
        **blocks : array_like, each shape (k,) or (k, P)
            The first-order blocks (:meth:`with_block`) by name.
        """
        parts = {"theta": theta, "hub_position": hub_position, "q": q,
                 "theta_dot": theta_dot, "hub_velocity": hub_velocity, "q_dot": q_dot}
        order = (["theta"] if self.rotation else []) + (["hub_position"] if self.free_hub
                                                        else []) + ["q"]
        order += [{"theta": "theta_dot", "hub_position": "hub_velocity",
                   "q": "q_dot"}[k] for k in order]
        sizes = {"theta": 1, "theta_dot": 1, "hub_position": 2, "hub_velocity": 2,
                 "q": self.n_modes, "q_dot": self.n_modes}
        unknown = set(blocks) - set(dict(self.extra))
        if unknown:
            raise InputValueError(f"state blocks must be among {list(dict(self.extra))}; got "
                                  f"{sorted(unknown)}")
        values = [(parts[k], sizes[k]) for k in order]
        values += [(blocks.get(name), len(labels)) for name, labels in self.extra]
        if any(_is_symbolic(v) for v, _ in values if v is not None):
            import casadi as ca
            return ca.vertcat(*[ca.DM.zeros(size) if v is None else v for v, size in values])
        arrays = [(None if v is None else _block_array(v, size), size) for v, size in values]
        widths = {a.shape[1] for a, _ in arrays if a is not None and a.ndim == 2}
        if len(widths) > 1:
            raise InputValueError(f"state blocks must share one number of columns; got "
                                  f"{sorted(widths)}")
        tail = tuple(widths)
        return np.concatenate([np.zeros((size,) + tail) if a is None
                               else np.broadcast_to(a if a.ndim == 2 or not tail
                                                    else a[:, None], (size,) + tail)
                               for a, size in arrays], axis=0)

    def from_beam(self, beam_states, theta=0.0, theta_dot=0.0):
        """The full state from the states of :meth:`without_rotation` and a prescribed hub angle
        and rate.

        Parameters
        ----------
        beam_states : array_like, shape (m,) or (m, P)
            States of :meth:`without_rotation`, in its order (``m = n_mechanical - 2``).
        theta : float or array_like, shape (P,), optional
            Hub angle, rad. Default 0.
        theta_dot : float or array_like, shape (P,), optional
            Hub rate, rad/s. Default 0.

        Returns
        -------
        ndarray, shape (n_mechanical,) or (n_mechanical, P)
            The mechanical states; first-order blocks are not included.
        """
        beam_states = np.asarray(beam_states, dtype=float)
        if beam_states.shape[:1] != (self.beam.size,) or beam_states.ndim > 2:
            raise InputValueError(f"beam states must have shape ({self.beam.size},) or "
                                  f"({self.beam.size}, P); got {beam_states.shape}")
        width = beam_states.shape[1:]
        out = np.zeros((self.n_mechanical,) + width)
        out[self.beam] = beam_states
        out[self.theta] = theta
        out[self.theta_dot] = theta_dot
        return out

    def zeros(self) -> np.ndarray:
        """The state at rest, shape (n,)."""
        return np.zeros(self.n_states)

    def __repr__(self):
        apps = ", ".join(f"{name or 'beam'}: {modes} modes" for name, modes in self.appendages)
        hub = "free hub" if self.free_hub else "pinned hub"
        extra = "".join(f", {name} ({len(labels)})" for name, labels in self.extra)
        return f"StateLayout({hub}, {apps}{extra}; {self.n_states} states)"


@lru_cache(maxsize=256)
def _projection(layout: StateLayout, other: StateLayout) -> np.ndarray:
    return layout._projection(other)
