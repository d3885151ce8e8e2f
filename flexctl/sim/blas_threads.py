"""The threads of the OpenBLAS libraries under numpy, SciPy, CasADi and slycot.

The wheels of numpy, SciPy, CasADi and slycot (python-control's) each carry an OpenBLAS that
starts one thread per core and, after a call it shared out, keeps the spare threads spinning
for a while, waiting for more work. flexctl's matrices are a few dozen rows: sharing them
out gains nothing, and the spinning threads take a core from the work beside them (an
accuracy check on a spare core, another worker process of a sweep). Measured on two cores:
``solve_slew`` on slew-90's exact design model took the same wall time with SciPy's OpenBLAS
on one thread and on two (0.085 s) and half the CPU time; ``flexctl demo`` went from about
46 s to 44 s.

The command line (``flexctl``) and the test suite put every one of them on
:data:`DEFAULT_THREADS` thread; a program that imports flexctl keeps its own settings unless
it calls :func:`limit_blas_threads` or sets ``FLEXCTL_BLAS_THREADS`` (a count, applied when
flexctl is imported; for the command line, ``0`` leaves the libraries' own choice).
"""

from __future__ import annotations

import ctypes
import glob
import os
from pathlib import Path

__all__ = ["limit_blas_threads", "DEFAULT_THREADS", "MAX_THREADS"]

#: Threads of each OpenBLAS under the command line and the test suite.
DEFAULT_THREADS = 1
#: Most threads :func:`limit_blas_threads` takes (OpenBLAS's own builds stop at 64 to 512).
MAX_THREADS = 1024
#: ``(package, library file pattern beside it, setter, getter)`` of each OpenBLAS.
_LIBRARIES = (
    # the wheel holds three copies; its plugins (IPOPT's MUMPS) load the one of this soname
    ("casadi", "casadi/libcasadi-tp-openblas.so.0", "openblas_set_num_threads",
     "openblas_get_num_threads"),
    ("scipy", "scipy.libs/libscipy_openblas-*.so*", "scipy_openblas_set_num_threads",
     "scipy_openblas_get_num_threads"),
    ("numpy", "numpy.libs/libscipy_openblas64_*.so*", "scipy_openblas_set_num_threads64_",
     "scipy_openblas_get_num_threads64_"),
    # python-control's slycot
    ("slycot", "slycot.libs/libscipy_openblas-*.so*", "scipy_openblas_set_num_threads",
     "scipy_openblas_get_num_threads"),
)


def _found() -> list:
    """``(package, library, setter, getter)`` of each OpenBLAS present (a conda build, or
    another platform, may have none of these files: then nothing is found)."""
    import importlib.util

    found = []
    for package, pattern, setter, getter in _LIBRARIES:
        spec = importlib.util.find_spec(package)
        if spec is None or not spec.submodule_search_locations:
            continue
        site = Path(list(spec.submodule_search_locations)[0]).resolve().parent
        for path in sorted(glob.glob(str(site / pattern)))[:1]:
            try:
                library = ctypes.CDLL(path)
                set_threads, get_threads = getattr(library, setter), getattr(library, getter)
            except (OSError, AttributeError):
                continue
            set_threads.argtypes, get_threads.restype = [ctypes.c_int], ctypes.c_int
            found.append((package, set_threads, get_threads))
    return found


def limit_blas_threads(count: int = DEFAULT_THREADS) -> dict:
    """Put the OpenBLAS of numpy, SciPy, CasADi and slycot on ``count`` threads (1 to
    :data:`MAX_THREADS`).

    Parameters
    ----------
    count : int, optional
        Threads per library, 1 to :data:`MAX_THREADS`. Default :data:`DEFAULT_THREADS`.

    Returns
    -------
    dict
        ``{package: threads it now has}`` for each OpenBLAS found (empty where the packages
        use another BLAS).

    Examples
    --------
    >>> set(limit_blas_threads(1).values()) <= {1}
    True
    """
    from ..model.checks import check_integer

    count = check_integer("limit_blas_threads", "count", count, minimum=1,
                          maximum=MAX_THREADS)
    threads = {}
    for package, set_threads, get_threads in _found():
        set_threads(count)
        threads[package] = int(get_threads())
    return threads


def threads_from_environment(default: int | None = None) -> dict:
    """Apply ``FLEXCTL_BLAS_THREADS`` (a count; ``0``: leave the libraries alone), else
    ``default`` (None: leave them alone). A value that is not an integer from 0 to
    :data:`MAX_THREADS` is ignored (``default`` applies): importing flexctl never fails on
    it.

    Parameters
    ----------
    default : int, optional
        Threads to set when the variable is unset or invalid. Default None: leave the
        libraries alone.

    Returns
    -------
    dict
        As :func:`limit_blas_threads` returns; empty when the libraries are left alone.
    """
    text = os.environ.get("FLEXCTL_BLAS_THREADS", "").strip()
    try:
        count = int(text) if text else default
    except ValueError:
        count = default
    if count is not None and not 0 <= count <= MAX_THREADS:
        count = default
    return limit_blas_threads(count) if count is not None and count > 0 else {}
