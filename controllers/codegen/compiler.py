"""The C compiler of an export: the checking flags, finding the compiler, running it and the
message of a compiler that fails (:class:`CompileError`)."""

from __future__ import annotations

import os
import shutil
import subprocess

__all__ = ["C_FLAGS", "MESSAGE_LINES", "CompileError", "find_compiler", "compiler_of",
           "run_compiler", "failure_message"]

#: Flags every export is checked with.
C_FLAGS = ("-std=c99", "-O2", "-Wall", "-Wextra", "-Werror")
#: Lines of the compiler's messages a :class:`CompileError` shows whole; of longer messages it
#: shows the first tenth of these and the last 40 (the first error and the last).
MESSAGE_LINES = 60


class CompileError(RuntimeError):
    """The C compiler refused an export (its messages attached), or there is none."""


def find_compiler(cc: str | None = None) -> str:
    """The C compiler's path: ``cc``, else ``$CC``, else ``cc``/``gcc``/``clang`` on the path.

    Parameters
    ----------
    cc : str, optional
        A compiler's name or path, tried first. Default: none given.

    Raises
    ------
    CompileError
        If none of them is found.
    """
    return compiler_of(cc)[1]


def compiler_of(cc: str | None = None) -> tuple:
    """``(name, path)`` of the C compiler :func:`find_compiler` finds: the name as given.

    Parameters
    ----------
    cc : str, optional
        A compiler's name or path, tried first. Default: none given.
    """
    for name in ([cc] if cc else []) + [os.environ.get("CC")] + ["cc", "gcc", "clang"]:
        if name and shutil.which(name):
            return name, shutil.which(name)
    raise CompileError("no C compiler found (set CC, or install cc, gcc or clang)")


def run_compiler(name: str, command: list, doing: str, cwd) -> str:
    """Run the compiler (or binutil) ``name`` in ``cwd``; a failure raises a
    :class:`CompileError` saying what it was ``doing``, with its messages.

    Parameters
    ----------
    name : str
        The tool as given (``$CC``, ``cc``, ...), for the messages.
    command : list of str
        The command line; ``command[0]`` is the tool's path.
    doing : str
        What it is asked to do (``"compiling flexctl_ctrl.c with ..."``).
    cwd : str or pathlib.Path
        Folder it runs in.

    Returns
    -------
    str
        What it printed on its standard output.
    """
    try:
        done = subprocess.run(command, capture_output=True, text=True, cwd=cwd)
    except OSError as exc:
        raise CompileError(f"the C compiler {name!r} could not be run ({doing}): "
                           f"{exc.strerror or exc}") from None
    if done.returncode != 0:
        raise CompileError(failure_message(name, done.returncode, done.stderr, done.stdout,
                                           doing))
    return done.stdout


def failure_message(name: str, status: int, stderr: str, stdout: str = "",
                     doing: str = "") -> str:
    """The message of a compiler that failed: its name, exit status and what it printed.

    Parameters
    ----------
    name : str
        The compiler as given (``$CC``, ``cc``, ...).
    status : int
        Its exit status (negative: the signal that stopped it).
    stderr, stdout : str
        What it printed (both shown, error stream first; of more than
        :data:`MESSAGE_LINES` lines, the first few and the last 40).
    doing : str, optional
        What it was asked to do (``"compiling flexctl_ctrl.c with ..."``).

    Returns
    -------
    str

    Examples
    --------
    >>> failure_message("false", 1, "")
    "the C compiler 'false' exited with status 1 and printed nothing"
    >>> print(failure_message("cc", 1, "a.c:1: error: x\\n", doing="compiling a.c"))
    the C compiler 'cc' exited with status 1 compiling a.c:
    a.c:1: error: x
    """
    ended = f"exited with status {status}" if status >= 0 else f"was stopped by signal {-status}"
    lines = [line.rstrip() for text in (stderr, stdout) for line in (text or "").splitlines()]
    while lines and not lines[-1]:
        lines.pop()
    while lines and not lines[0]:
        lines.pop(0)
    what = f" {doing}" if doing else ""
    if not lines:
        return f"the C compiler {name!r} {ended} and printed nothing" + (
            f" ({doing})" if doing else "")
    if len(lines) > MESSAGE_LINES:
        head = MESSAGE_LINES // 10
        lines = lines[:head] + [f"[... {len(lines) - head - 40} lines left out ...]"] \
            + lines[-40:]
    return f"the C compiler {name!r} {ended}{what}:\n" + "\n".join(lines)
