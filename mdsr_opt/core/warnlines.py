"""Python warnings as one clean line each: ``warning: FabricationWarning: ...``, not a file path and a line of
source code.

The ``mdsr`` command shows the warnings raised while it works (:class:`~mdsr_opt.synthesis.fabrication.
FabricationWarning`, ``MuscleWarning``, ...) through :func:`warnings_as_log_lines`: each becomes one
record of the ``mdsr_opt.core.warnlines`` logger at level WARNING, so it is printed like the other log lines and
also under ``-q`` (which keeps warnings, errors and results). The worker processes of a run's pool
(:mod:`mdsr_opt.core.jobs`) print theirs as the same one line on stderr (:func:`one_line_warnings`).
A script that imports the package keeps Python's own display.

Example
-------
>>> import warnings
>>> warning_line(UserWarning("first line\\nsecond"), UserWarning)
'warning: UserWarning: first line second'
"""

from __future__ import annotations

import contextlib
import logging
import sys
import warnings

__all__ = ["warning_line", "warnings_as_log_lines", "one_line_warnings"]

_LOG = logging.getLogger(__name__)


def warning_line(message, category) -> str:
    """One line for a warning: ``warning: <category>: <message>`` with the message's line breaks as spaces."""
    text = " ".join(str(message).split())
    return f"warning: {getattr(category, '__name__', category)}: {text}"


@contextlib.contextmanager
def warnings_as_log_lines():
    """Within the block, a warning that Python would display is one WARNING record of the
    ``mdsr_opt.core.warnlines`` logger (:func:`warning_line`); warnings recorded by ``catch_warnings(record=True)``
    or filtered out are not affected. Python's display is back after the block."""
    before = warnings.showwarning

    def show(message, category, filename, lineno, file=None, line=None):
        _LOG.warning(warning_line(message, category))

    warnings.showwarning = show
    try:
        yield
    finally:
        if warnings.showwarning is show:
            warnings.showwarning = before


def one_line_warnings() -> None:
    """From now on, this process displays each warning as one line on stderr (:func:`warning_line`): for
    the worker processes of a pool, whose output goes beside their command's log lines."""
    def show(message, category, filename, lineno, file=None, line=None):
        stream = file or sys.stderr  # as Python's own display: the stream's write, no print
        try:
            stream.write(warning_line(message, category) + "\n")
            stream.flush()
        except (OSError, AttributeError):  # stderr gone (or None): nothing to tell it to
            pass

    warnings.showwarning = show
