"""The project's exceptions for bad input: what a user gave, not what the code did.

Every check of an argument, a parameter or a scene value raises one of these, with a message
naming the input (its field path, e.g. ``beam.density`` or ``masses[0].position``), the rule
and the value received. They derive from the built-in ``ValueError`` / ``TypeError``, so code
that catches those keeps working, while the command line can tell bad input (exit 2, one line)
from a genuine bug (exit 1, with its traceback) by catching :class:`InputError` alone.

Examples
--------
>>> from flexctl.model.errors import InputError, InputValueError
>>> err = InputValueError("beam.length must be positive; got -1.0")
>>> isinstance(err, ValueError), isinstance(err, InputError)
(True, True)
"""

from __future__ import annotations

__all__ = ["InputError", "InputValueError", "InputTypeError", "SingularMassMatrixError"]


class InputError(Exception):
    """Base of the bad-input errors; catch it to report bad input in one line."""


class InputValueError(InputError, ValueError):
    """An input of the right type with a wrong value (out of range, non-finite, ...)."""


class InputTypeError(InputError, TypeError):
    """An input of the wrong type (a string where a number belongs, a non-callable, ...)."""


class SingularMassMatrixError(ArithmeticError):
    """The mass matrix of the model is singular at the given state (not bad input: a state
    the model cannot take)."""

