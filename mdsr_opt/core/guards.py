"""Guards around calls into C solvers: Ctrl-C during a CasADi solve, and the C-level standard output
that solvers print to whatever Python's ``sys.stdout`` says."""

from __future__ import annotations

import contextlib
import os
import signal
import sys
import tempfile
import threading

__all__ = ["interruptible", "quiet_stdout", "captured_stdout", "request_stop", "cancel_stop"]

#: thread id -> the exception :func:`interruptible` raises when a solve in that thread returns
_STOPS: dict[int, type] = {}


def request_stop(thread_id: int, exc_type: type) -> None:
    """Make the next solve of thread ``thread_id`` that returns inside :func:`interruptible` raise
    ``exc_type`` (until :func:`cancel_stop`): a time budget set from another thread. An asynchronous exception
    alone can land in a solver's Python callback, where CasADi turns it into a failed evaluation that load
    stepping takes for a failed step."""
    _STOPS[int(thread_id)] = exc_type


def cancel_stop(thread_id: int) -> None:
    """Withdraw :func:`request_stop` for thread ``thread_id``."""
    _STOPS.pop(int(thread_id), None)


def _raise_requested_stop() -> None:
    exc_type = _STOPS.get(threading.get_ident())
    if exc_type is not None:
        raise exc_type("stop requested during a solve")


@contextlib.contextmanager
def quiet_stdout(active: bool):
    """Silence C-level stdout (Uno prints notes about fixed variables whatever its logger says)."""
    if not active:
        yield
        return
    sys.stdout.flush()
    saved = os.dup(1)
    devnull = os.open(os.devnull, os.O_WRONLY)
    try:
        os.dup2(devnull, 1)
        yield
    finally:
        os.dup2(saved, 1)
        os.close(saved)
        os.close(devnull)


@contextlib.contextmanager
def interruptible():
    """Make Ctrl-C (SIGINT) during a CasADi solve raise :class:`KeyboardInterrupt` when the solver returns.

    CasADi catches the interrupt inside a solve: IPOPT then stops after the current iteration and reports
    ``NonIpopt_Exception_Thrown`` (printing a ``KeyboardInterruptException`` warning), a status that other
    errors share and that load stepping would take for a failed step. Inside this context a SIGINT is
    recorded on its way to the previous handler, and the recorded :class:`KeyboardInterrupt` is raised
    again on exit, so the solve's outcome is never used. Nesting is fine; outside the main thread (where
    signal handlers cannot be set) and when SIGINT is ignored this does nothing.

    Example
    -------
    >>> with interruptible():
    ...     pass  # sol = solver(x0=..., lbx=..., ubx=...)
    """
    prev = signal.getsignal(signal.SIGINT) if threading.current_thread() is threading.main_thread() else None
    if not callable(prev):  # not the main thread, SIG_IGN or SIG_DFL: nothing to record
        try:
            yield
        except Exception:  # a failed solve: a requested stop is what stopped it
            _raise_requested_stop()
            raise
        _raise_requested_stop()
        return
    caught: list[BaseException] = []

    def handler(signum, frame):
        try:
            prev(signum, frame)
        except BaseException as exc:  # KeyboardInterrupt from the default handler (or the user's handler)
            caught.append(exc)
            raise

    def recorded():
        exc = caught[0]
        if isinstance(exc, KeyboardInterrupt) and not exc.args:
            exc = KeyboardInterrupt("interrupted (SIGINT) during a solve")
        return exc

    signal.signal(signal.SIGINT, handler)
    try:
        yield
    except Exception as exc:  # e.g. a CasADi Function call whose error replaced the interrupt it swallowed
        if caught:
            raise recorded() from exc
        _raise_requested_stop()
        raise
    finally:
        signal.signal(signal.SIGINT, prev)
    if caught:
        raise recorded()
    _raise_requested_stop()


@contextlib.contextmanager
def captured_stdout(sink: list):
    """Capture C-level stdout (IPOPT prints why it rejects an option) into ``sink`` as one string."""
    import io

    sys.stdout.flush()
    saved = os.dup(1)
    text = io.StringIO()  # CasADi's Python build prints through sys.stdout, other builds to file descriptor 1
    with tempfile.TemporaryFile(mode="w+b") as fh:
        os.dup2(fh.fileno(), 1)
        try:
            with contextlib.redirect_stdout(text):
                yield
        finally:
            os.dup2(saved, 1)
            os.close(saved)
            fh.seek(0)
            sink.append(text.getvalue() + fh.read().decode("utf-8", "replace"))
