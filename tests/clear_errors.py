"""The property tests' verdict on an exception: the project's own bad-input error, naming the
input it refuses."""

from hypothesis import event

from flexctl.model.errors import InputError


def assert_clear_error(exc, *names):
    """``exc`` is an :class:`~flexctl.model.errors.InputError` whose message names one of
    ``names`` (any message when none is given); counted as a hypothesis event."""
    assert isinstance(exc, InputError), f"{type(exc).__name__} escaped: {exc}"
    if names:
        assert any(name in str(exc) for name in names), str(exc)
    event(f"clear error: {type(exc).__name__}")
