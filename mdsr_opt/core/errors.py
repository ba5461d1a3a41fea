"""The user's mistakes and the package's own: :class:`InputError` and what a command makes of an exception.

Bad input (a value, a name, a file or its content) is reported in one line with exit code 2; anything
else that escapes a command is a bug of the package and is shown with its traceback (exit code 1). The
distinction is made by design, not by the exception's built-in type: a ``ValueError`` raised deep inside a
solve is a bug even though the same type also says "bad argument" at a function's door.

- :class:`InputError` (a ``ValueError``; :class:`InputTypeError` also a ``TypeError``) marks bad input.
  The package's own input errors derive from it (an unknown name, a malformed scene file, an unusable
  output folder), so Python code that catches ``ValueError`` sees no change.
- :func:`checking_input` turns the ``ValueError``/``TypeError`` of the checks made within it into
  :class:`InputError`: a command wraps its checks of the arguments and the loading of its scenes in it,
  before any work, and a public function whose door a command reaches only while working (a study's
  plan, a folder of photographs) wraps its own door.
- :func:`exit_report` says what a command ends with and gives its exit code.

Example
-------
>>> with checking_input():
...     float("many")
Traceback (most recent call last):
...
mdsr_opt.core.errors.InputError: could not convert string to float: 'many'
"""

from __future__ import annotations

import contextlib
import traceback

__all__ = ["InputError", "InputTypeError", "LayoutError", "checking_input", "exit_report"]


class InputError(ValueError):
    """Bad input from the user: a value, a name, a file or its content (the message says which). The
    ``mdsr`` command reports it in one line with exit code 2."""


class InputTypeError(InputError, TypeError):
    """An input of the wrong type (an :class:`InputError` that is also a ``TypeError``)."""


class LayoutError(ValueError):
    """A muscle layout that cannot work on its body: a muscle's end patches joined through other muscles'
    patches, or covering so much of it that it cannot contract; or ropes the routing cannot lay on this body,
    mesh and target (a body too thin for the ropes' inset, a mesh too coarse for it, a channel or fixture
    the body cannot hold, ``symmetry=True`` on a target that is not mirror-symmetric). A routed layout can be
    one (the data a stage made, not the user's input): ``mdsr run`` fails the case and goes on (exit code
    1); a function given such muscles or sizes raises it as the ``ValueError`` it is (at a command's door,
    :func:`checking_input` makes it bad input, exit code 2)."""


@contextlib.contextmanager
def checking_input():
    """Within the block, a ``ValueError`` or ``TypeError`` is bad input: raised again as :class:`InputError`
    (:class:`InputTypeError` for a ``TypeError``) with the same message, the original as its cause. For the
    checks at a door, before any work."""
    try:
        yield
    except InputError:
        raise
    except TypeError as exc:
        raise InputTypeError(str(exc)) from exc
    except ValueError as exc:
        raise InputError(str(exc)) from exc


def exit_report(prog: str, exc: Exception) -> tuple[int, str]:
    """How the command ``prog`` ends on ``exc``: ``(exit code, text for stderr)``.

    :class:`InputError` and ``OSError`` (an unusable file or folder): one line ``prog: error: ...``, 2.
    Anything else is a bug of the package: its traceback, then a line saying so, 1.

    Example
    -------
    >>> exit_report("mdsr run", InputError("unknown scene 'geko'"))
    (2, "mdsr run: error: unknown scene 'geko'")
    """
    if isinstance(exc, InputError):
        return 2, f"{prog}: error: {exc}"
    if isinstance(exc, OSError):
        text = f"{exc.strerror or type(exc).__name__}: {exc.filename}" if exc.filename else str(exc)
        return 2, f"{prog}: error: {text}"
    trace = "".join(traceback.format_exception(type(exc), exc, exc.__traceback__))
    return 1, (f"{trace}{prog}: internal error: {type(exc).__name__}: {exc}\nThis is a bug in mdsr_opt, not a "
               "problem with your input; please report it with the traceback above.")
