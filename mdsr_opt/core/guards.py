"""Guards around calls into C solvers: Ctrl-C during a solve, and the C-level standard output that solvers
print to whatever Python's ``sys.stdout`` says.

How Ctrl-C stops a solve
------------------------
:func:`interruptible` installs, for the length of a solve and on the main thread only, a SIGINT handler that
calls the previous one (Python's default raises :class:`KeyboardInterrupt` where the program is) and records
what it raised; the previous handler is put back when the block ends. The exception raised where the signal
landed is not enough: inside a CasADi solve it lands in a Python callback (the numpy energy, the iteration
callback), where CasADi may turn it into a failed evaluation that the solver answers with a shorter step or a
restoration phase, and a load-stepping loop with a failed step. So the record is also a flag: the solvers'
iteration callbacks (:func:`stop_requested`; IPOPT, sqpmethod and Uno stop at the next iteration) and the
package's own loops (:func:`check_stop`) look at it, and the block raises the recorded
:class:`KeyboardInterrupt` when the solver returns, so its outcome is never used. Inside a CasADi NLP solver
the handler only records: raised there, the interrupt would abort the solver with a warning of CasADi's on
stderr, and the record stops it at its next iteration anyway. A previous handler that
does not raise (a program's own) is left to decide: nothing is recorded and the solve goes on. A process
that was started with SIGINT ignored (a background job of a non-interactive shell, ``nohup``) is not
interrupted by it, in a solve or elsewhere: Python then raises no :class:`KeyboardInterrupt` at all.

:func:`request_stop` is the same stop asked for from another thread (a study's time budget).
"""

from __future__ import annotations

import contextlib
import io
import os
import signal
import sys
import tempfile
import threading

__all__ = ["interruptible", "stop_requested", "check_stop", "quiet_stdout", "captured_stdout", "request_stop",
           "cancel_stop"]

#: thread id -> the exception that stops a solve of that thread (see :func:`request_stop`)
_STOPS: dict[int, type] = {}

#: what the SIGINT handler of an :func:`interruptible` block raised (at most one exception), kept until the
#: outermost block on the main thread ends
_SIGINT: list[BaseException] = []

#: nesting depth of :func:`interruptible` blocks that installed their handler (main thread only)
_DEPTH = [0]


def request_stop(thread_id: int, exc_type: type) -> None:
    """Make the solve of thread ``thread_id`` inside :func:`interruptible` stop at its next iteration and
    raise ``exc_type`` (until :func:`cancel_stop`): a time budget set from another thread. An asynchronous
    exception alone can land in a solver's Python callback, where CasADi turns it into a failed evaluation
    that load stepping takes for a failed step."""
    _STOPS[int(thread_id)] = exc_type


def cancel_stop(thread_id: int) -> None:
    """Withdraw :func:`request_stop` for thread ``thread_id``."""
    _STOPS.pop(int(thread_id), None)


def _raise_requested_stop() -> None:
    exc_type = _STOPS.get(threading.get_ident())
    if exc_type is not None:
        raise exc_type("stop requested during a solve")


def _on_main_thread() -> bool:
    return threading.current_thread() is threading.main_thread()


def _recorded() -> BaseException:
    exc = _SIGINT[0]
    if isinstance(exc, KeyboardInterrupt) and not exc.args:
        exc = _SIGINT[0] = KeyboardInterrupt("interrupted (SIGINT) during a solve")
    return exc


def stop_requested() -> bool:
    """Should the solve running in this thread stop now? True after a SIGINT inside :func:`interruptible`
    (main thread) or a :func:`request_stop` for this thread. What solvers' iteration callbacks ask."""
    return bool(_SIGINT) and _on_main_thread() or threading.get_ident() in _STOPS


def check_stop() -> None:
    """Raise the recorded :class:`KeyboardInterrupt` (or the requested stop) if :func:`stop_requested`: for
    loops and callbacks inside a solve, where an interrupt raised earlier may have been swallowed (an
    evaluation CasADi reported as failed, a factorisation taken as singular)."""
    if _SIGINT and _on_main_thread():
        raise _recorded()
    _raise_requested_stop()


def _inside_a_solver(frame) -> bool:
    """Whether ``frame`` (where a signal's handler runs) is inside a call of a CasADi NLP solver: one of its
    callers is CasADi's Python call of a ``Function`` that is an ``Nlpsol`` (a callback the solver runs,
    or the solver's own signal check, has that call above it)."""
    casadi = sys.modules.get("casadi")
    while casadi is not None and frame is not None:
        if str(frame.f_globals.get("__name__", "")).partition(".")[0] == "casadi":
            fn = frame.f_locals.get("self")
            if isinstance(fn, casadi.Function) and fn.is_a("Nlpsol", True):
                return True
        frame = frame.f_back
    return False


@contextlib.contextmanager
def interruptible():
    """Make Ctrl-C (SIGINT) during a solve stop it and raise :class:`KeyboardInterrupt`, never a result.

    See the module docstring: within the block a SIGINT goes to the previous handler, and what that raises
    (Python's default: :class:`KeyboardInterrupt`) is recorded; the solvers' iteration callbacks then stop
    at the next iteration (:func:`stop_requested`) and the block raises the recorded exception when the
    solver returns, also when the solve swallowed it or failed because of it. The handler is installed on
    the main thread only (signal handlers cannot be set elsewhere) and not when SIGINT is ignored or left
    to the system's default; a stop asked for by :func:`request_stop` is raised in any thread. Nesting is
    fine: the record is kept until the outermost block ends.

    Example
    -------
    >>> with interruptible():
    ...     pass  # sol = solver(x0=..., lbx=..., ubx=...)
    """
    prev = signal.getsignal(signal.SIGINT) if _on_main_thread() else None
    if not callable(prev):  # not the main thread, SIG_IGN or SIG_DFL: nothing to record
        try:
            yield
        except Exception:  # a failed solve: a requested stop is what stopped it
            _raise_requested_stop()
            raise
        _raise_requested_stop()
        return

    def handler(signum, frame):
        if _SIGINT:  # a second Ctrl-C in the same block: raised wherever it lands (a solver stuck in one
            raise _recorded()  # iteration is then aborted, with CasADi's warning)
        try:
            prev(signum, frame)
        except BaseException as raised:  # KeyboardInterrupt from the default handler (or the program's)
            _SIGINT.append(raised)
            exc = raised
        else:
            return  # the program's own handler decided to go on
        if not _inside_a_solver(frame):
            raise exc
        # inside a CasADi NLP solver (its signal check between evaluations, or a Python callback it runs) the
        # interrupt would abort the solver with a warning of CasADi's on stderr: the record alone stops the
        # solver at its next iteration, and the block raises the interrupt when the solver returns

    signal.signal(signal.SIGINT, handler)
    _DEPTH[0] += 1
    try:
        yield
    except Exception as exc:  # e.g. a CasADi Function call whose error replaced the interrupt it swallowed
        if _SIGINT:
            raise _recorded() from exc
        _raise_requested_stop()
        raise
    finally:
        signal.signal(signal.SIGINT, prev)
        _DEPTH[0] -= 1
        pending = _recorded() if _SIGINT else None
        if _DEPTH[0] == 0:
            _SIGINT.clear()
    if pending is not None:
        raise pending
    _raise_requested_stop()


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
def captured_stdout(sink: list):
    """Capture C-level stdout (IPOPT prints why it rejects an option) into ``sink`` as one string."""
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
