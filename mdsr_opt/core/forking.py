"""Forking a job's process: the low-level steps :mod:`mdsr_opt.core.background` and
:mod:`mdsr_opt.core.forkserver` build on (when a fork is safe, the child's life from the fork to
``os._exit``, reading its answer, collecting it, signalling it).
"""

from __future__ import annotations

import os
import pickle
import resource
import signal
import sys
import threading
import traceback
import warnings

__all__ = ["child_main", "die_with_parent", "fork_is_safe", "fork_quietly", "read_all", "reap", "send_signal",
           "write_all"]


def fork_is_safe() -> bool:
    """Whether :class:`~mdsr_opt.core.background.BackgroundWriter` (or a
    :class:`~mdsr_opt.core.forkserver.ForkServer`) may fork here: Linux, two or more cores available to this process,
    called from the main thread with no other Python thread alive."""
    if not sys.platform.startswith("linux") or not hasattr(os, "fork"):
        return False
    try:
        cores = len(os.sched_getaffinity(0))
    except (AttributeError, OSError):  # pragma: no cover - Linux always has it
        cores = os.cpu_count() or 1
    return (cores >= 2 and threading.current_thread() is threading.main_thread()
            and threading.active_count() == 1)


def fork_quietly() -> int:
    """``os.fork()`` after flushing stdout and stderr (nothing buffered before the fork is written twice),
    without Python's (>= 3.12) warning of a fork in a process with native threads: ours are OpenBLAS's idle
    pool, which OpenBLAS's fork handlers take care of. The caller holds Ctrl-C back around it."""
    sys.stdout.flush()
    sys.stderr.flush()
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", DeprecationWarning)
        return os.fork()


def die_with_parent(parent: int, sig: int = signal.SIGKILL) -> None:  # pragma: no cover - in the child
    """Have the kernel kill this child when its parent dies (Linux ``PR_SET_PDEATHSIG``): a run killed
    outright must not leave children writing into its folder after the next run has taken it over. A
    jobs' server's children are interrupted instead (``sig`` ``SIGINT``: they remove their temporary
    files), since the server is killed when the run stops, and dies with the run's process."""
    import ctypes

    try:
        libc = ctypes.CDLL(None, use_errno=True)
        libc.prctl(1, int(sig), 0, 0, 0)  # 1 = PR_SET_PDEATHSIG
    except (OSError, AttributeError):
        pass
    if os.getppid() != parent:  # the parent died before the request took effect
        os._exit(1)


def child_main(w: int, fn, args, kwargs, parent: int, mask, served: bool = False) -> None:  # pragma: no cover
    """Run the job, send ``(status, value, traceback, CPU seconds)`` through ``w`` and leave with
    ``os._exit`` (never returning into the parent's stack, its ``finally`` blocks or its exit handlers).
    A jobs' server's child (``served``) first sends its pid (8 bytes), and leaves at once if nobody reads."""
    code = 1
    try:
        # the parent's stop() interrupts us; set first, as a server's child inherits the server's own
        # SIGINT handler (which only notes the interrupt) and must not lose the death signal asked below
        signal.signal(signal.SIGINT, signal.default_int_handler)
        if served:  # first thing: a stopping caller then always knows whom to kill
            os.write(w, os.getpid().to_bytes(8, "little"))  # BrokenPipeError: the run has stopped
        die_with_parent(parent, signal.SIGINT if served else signal.SIGKILL)
        signal.pthread_sigmask(signal.SIG_SETMASK, mask)  # from here on (held back during the fork)
        try:
            payload = ("ok", fn(*args, **kwargs), "")
            code = 0
        except BaseException as exc:  # noqa: BLE001 - everything goes back to the parent
            payload = ("error", exc, traceback.format_exc())
        # the job's CPU time, with what it waited for (as the kernel's accounting of a child includes it)
        cpu = sum(u.ru_utime + u.ru_stime for u in (resource.getrusage(resource.RUSAGE_SELF),
                                                    resource.getrusage(resource.RUSAGE_CHILDREN)))
        try:
            data = pickle.dumps(payload + (cpu,))
        except Exception:  # noqa: BLE001 - an unpicklable result or exception: its text goes instead
            kind = "error" if payload[0] == "error" else "unpicklable result"
            data = pickle.dumps(("error", RuntimeError(f"{kind}: {payload[1]!r}"[:2000]), payload[2], cpu))
            code = 1
        write_all(w, data)
        sys.stdout.flush()
        sys.stderr.flush()
    except BaseException:  # noqa: BLE001 - nothing may escape into the parent's code
        pass
    finally:
        os._exit(code)


def write_all(fd: int, data: bytes) -> None:
    """Write ``data`` to ``fd`` whole (a pipe takes it in parts)."""
    view = memoryview(data)
    while view:
        view = view[os.write(fd, view):]


def read_all(fd: int, chunks: list) -> None:
    """Read ``fd`` to its end into ``chunks`` (what was read stays there if the reading is interrupted)."""
    while True:
        chunk = os.read(fd, 1 << 16)
        if not chunk:
            return
        chunks.append(chunk)


def reap(pid: int, block: bool) -> tuple[int, float] | None:
    """``(exit status, CPU seconds)`` of the child once it has ended (None while it runs)."""
    try:
        done, status, usage = os.wait4(pid, 0 if block else os.WNOHANG)
    except ChildProcessError:  # already reaped
        return -1, float("nan")
    if done == 0:
        return None
    return os.waitstatus_to_exitcode(status), usage.ru_utime + usage.ru_stime


def send_signal(pid: int, sig) -> None:
    try:
        os.kill(pid, sig)
    except ProcessLookupError:
        pass
