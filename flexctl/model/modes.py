"""Cantilever (clamped-free) modes of a uniform Euler-Bernoulli beam.

The mode shapes are those of :ref:`section 3 of the model <sec-modes>`,

    phi_i(xi) = cosh(z_i xi) - cos(z_i xi) - s_i (sinh(z_i xi) - sin(z_i xi)),

normalised so that ``int_0^l phi_i phi_j dx = l delta_ij`` and ``phi_i(l) = 2 (-1)^(i+1)``.
Evaluated as written, ``cosh`` and ``s_i sinh`` cancel and every digit is lost from about the
tenth mode on. Here the hyperbolic part is rewritten with exponentials,

    cosh(a) - s sinh(a) = (1 - s) e^a / 2 + (1 + s) e^-a / 2,

with ``1 - s = (sin z - cos z - e^-z) / (sinh z + sin z)`` computed without subtraction of
nearly equal numbers, and ``(1 - s) e^a`` formed as ``e^(a - z)`` times a bounded factor, so
that any number of modes stays accurate to machine precision.

Examples
--------
>>> import numpy as np
>>> from flexctl.model.modes import cantilever_roots
>>> np.round(cantilever_roots(3), 7)
array([1.8751041, 4.6940911, 7.8547574])
"""

from __future__ import annotations

from functools import lru_cache

import numpy as np

from .checks import check_integer
from .errors import InputValueError

__all__ = ["cantilever_roots", "mode_shapes"]


@lru_cache(maxsize=8)
def _roots(n_modes: int) -> tuple:
    roots = []
    for i in range(1, n_modes + 1):
        # cos z cosh z + 1 = 0  <=>  f(z) = cos z + sech z = 0, well scaled for every root.
        z = (2 * i - 1) * np.pi / 2 + (0.3042 if i == 1 else 0.0)
        for _ in range(100):
            sech = 1.0 / np.cosh(z)
            f = np.cos(z) + sech
            df = -np.sin(z) - sech * np.tanh(z)
            step = f / df
            z -= step
            if abs(step) < 1e-15 * z:
                break
        roots.append(z)
    return tuple(roots)


def cantilever_roots(n_modes: int) -> np.ndarray:
    """Roots ``z_i`` of ``cos z cosh z + 1 = 0``, ascending.

    Parameters
    ----------
    n_modes : int
        Number of roots, >= 1.

    Returns
    -------
    ndarray, shape (n_modes,)
    """
    return np.array(_roots(check_integer("cantilever_roots", "n_modes", n_modes, minimum=1)))


def _one_minus_s_scaled(z: np.ndarray) -> np.ndarray:
    """``(1 - s) e^z``, bounded for every root (about ``2 (sin z - cos z)``)."""
    emz = np.exp(-z)
    # sinh z + sin z = e^z (1 - e^-2z + 2 sin z e^-z) / 2
    return 2.0 * (np.sin(z) - np.cos(z) - emz) / (1.0 - emz ** 2 + 2.0 * np.sin(z) * emz)


def mode_shapes(n_modes: int, xi, derivative: int = 0, length: float = 1.0) -> np.ndarray:
    """Cantilever mode shapes or their derivatives at normalised positions.

    Parameters
    ----------
    n_modes : int
        Number of modes ``N``.
    xi : array_like, shape (P,)
        Positions ``x / l`` in ``[0, 1]``.
    derivative : {0, 1, 2, 3}
        Order of the derivative with respect to ``x``.
    length : float
        Beam length ``l``, m; derivatives carry the factor ``(z_i / l)^derivative``.

    Returns
    -------
    ndarray, shape (N, P)
        ``d^k phi_i / dx^k`` at each position, in m^-k.
    """
    if derivative not in (0, 1, 2, 3):
        raise InputValueError(f"derivative must be 0, 1, 2 or 3; got {derivative!r}")
    z = cantilever_roots(n_modes)[:, None]
    xi = np.atleast_1d(np.asarray(xi, dtype=float))[None, :]
    if np.any(xi < -1e-12) or np.any(xi > 1 + 1e-12):
        raise InputValueError("xi must lie in [0, 1]")
    a = z * xi
    s = (np.cosh(z) + np.cos(z)) / (np.sinh(z) + np.sin(z))
    grow = 0.5 * _one_minus_s_scaled(z) * np.exp(a - z)   # (1 - s) e^a / 2
    decay = 0.5 * (1.0 + s) * np.exp(-a)                   # (1 + s) e^-a / 2
    if derivative == 0:
        value = grow + decay - np.cos(a) + s * np.sin(a)
    elif derivative == 1:
        value = grow - decay + np.sin(a) + s * np.cos(a)
    elif derivative == 2:
        value = grow + decay + np.cos(a) - s * np.sin(a)
    else:
        value = grow - decay - np.sin(a) - s * np.cos(a)
    return value * (z / length) ** derivative
