"""BLAS threads (flexctl.sim.blas_threads): set where the libraries are found, refused by
name otherwise, and the command line's default reaches its worker processes."""

import os
import subprocess
import sys

import pytest

from flexctl.model.errors import InputError
from flexctl.sim.blas_threads import limit_blas_threads, threads_from_environment


def test_every_library_found_takes_the_count():
    found = limit_blas_threads(2)
    assert all(count == 2 for count in found.values())
    assert set(found) <= {"casadi", "scipy", "numpy", "slycot"}
    assert all(count == 1 for count in limit_blas_threads(1).values())


@pytest.mark.parametrize("bad", [0, -1, 1.5, "2", None, True, float("nan"), float("inf"),
                                 10 ** 12])
def test_bad_counts_are_refused(bad):
    with pytest.raises(InputError, match="count"):
        limit_blas_threads(bad)


def test_environment(monkeypatch):
    monkeypatch.setenv("FLEXCTL_BLAS_THREADS", "0")
    assert threads_from_environment(1) == {}              # 0: left alone
    for bad in ("many", "nan", "-3", "1e9", str(10 ** 12)):
        monkeypatch.setenv("FLEXCTL_BLAS_THREADS", bad)       # not a count: the default
        assert set(threads_from_environment(1).values()) <= {1}
        assert threads_from_environment() == {}
    monkeypatch.delenv("FLEXCTL_BLAS_THREADS")
    assert threads_from_environment() == {}


def test_import_applies_the_environment():
    code = ("import flexctl\nfrom flexctl.sim.blas_threads import _found\n"
            "print(sorted({int(get()) for _, _, get in _found()}))")
    env = {**os.environ, "FLEXCTL_BLAS_THREADS": "1"}
    out = subprocess.run([sys.executable, "-c", code], env=env, capture_output=True,
                         text=True, timeout=120)
    assert out.returncode == 0, out.stderr
    assert out.stdout.strip() in ("[1]", "[]")
