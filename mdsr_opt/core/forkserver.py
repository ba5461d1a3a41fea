"""The jobs' server: a process forked early that warms up beside its caller and forks the jobs it is sent.

``mdsr run`` spent its first 1.5-2 s on one core: imports, building the scene, and matplotlib's import and
warm-up, which every figure job needs and which had to be done in the process the jobs fork from. A
:class:`ForkServer` started before the scene is built does that warm-up on the second core; the jobs,
pickled, are forked from its warm memory. :class:`~mdsr_opt.core.background.BackgroundWriter` uses it with
``server=True``; :func:`serving` shares one server between the writers of a command.

The protocol: the caller sends each job as a memory file (``memfd_create``) with the write end of a pipe
over a Unix socket (``SCM_RIGHTS``), so a send never waits for the server, not even while it prepares; the
server forks a child for it, which sends its pid and then its answer through the pipe
(:func:`~mdsr_opt.core.forking.child_main`). The caller never waits for the server itself.
"""

from __future__ import annotations

import collections
import contextlib
import gc
import os
import pickle
import select
import signal
import socket
import threading
import time
import weakref
from typing import Any, Callable

from .forking import child_main, die_with_parent, fork_is_safe, fork_quietly, read_all, reap, send_signal, write_all

__all__ = ["ForkServer", "JobNotLoadable", "load_job", "serving", "shared_server"]


class ForkServer:
    """A process forked now that calls ``prepare`` and then forks the jobs :meth:`spawn` sends it, at most
    ``jobs`` at a time (None: no limit); the others wait in the server, in order, so that sending a job
    never waits for a slot.

    A job's arguments pickle in a few milliseconds (a :class:`~mdsr_opt.body.mesh.Mesh` leaves its solver
    caches behind), and in ``mdsr run gecko`` the copies drew as fast as the originals. The server dies
    with its caller (``SIGKILL``); its jobs are interrupted when it dies (``SIGINT``, so that they remove
    their temporary files). Where a server cannot run (see :func:`~mdsr_opt.core.forking.fork_is_safe`; no
    ``memfd_create``), :attr:`alive` is False and :meth:`spawn` returns None.
    """

    def __init__(self, prepare: Callable[[], Any] | None = None, jobs: int | None = 3):
        if jobs is not None and (isinstance(jobs, bool) or not isinstance(jobs, int) or jobs < 1):
            raise ValueError(f"jobs must be a positive integer or None, not {jobs!r}")
        self.pid = 0
        #: how the server ended: 0 when it exited by itself (after collecting its jobs), -9 when killed;
        #: None while it runs (or if it never started)
        self.returncode: int | None = None
        self._sock: socket.socket | None = None
        self._used = False  # sent a job (close() then lets it collect its jobs; else it is killed at once)
        if not (fork_is_safe() and hasattr(os, "memfd_create") and hasattr(socket, "send_fds")):
            return
        mine, theirs = socket.socketpair(socket.AF_UNIX, socket.SOCK_STREAM)
        parent = os.getpid()
        mask = signal.pthread_sigmask(signal.SIG_BLOCK, {signal.SIGINT})  # as in BackgroundWriter.submit
        try:
            pid = fork_quietly()
            if pid == 0:  # pragma: no cover - the server; never returns
                try:
                    mine.close()
                    _serve(theirs, prepare, parent, jobs)
                finally:
                    os._exit(1)
            self.pid, self._sock = pid, mine
            _LIVE.add(self)
        except BaseException:
            mine.close()
            raise
        finally:
            theirs.close()
            signal.pthread_sigmask(signal.SIG_SETMASK, mask)

    @property
    def alive(self) -> bool:
        """Whether jobs can be sent (the server was started and has not been killed or lost)."""
        return self._sock is not None

    def spawn(self, fn: Callable[..., Any], args: tuple = (), kwargs: dict | None = None) -> int | None:
        """Have the server fork a child that runs ``fn(*args, **kwargs)``; returns the read end of the
        child's pipe (its pid as 8 bytes, then its pickled answer, as
        :class:`~mdsr_opt.core.background.BackgroundWriter` reads it), or None when the job does not pickle
        or the server is gone (then run it otherwise)."""
        r, w = os.pipe()
        try:
            sent = self._send(b"j", (fn, args, kwargs or {}), w)
        except BaseException:  # Ctrl-C while sending: nothing of it stays open here
            os.close(r)
            raise
        if sent:
            return r
        os.close(r)
        return None

    def prepare(self, fn: Callable[[], Any]) -> bool:
        """Have the server call ``fn()`` in its own process before it forks the jobs sent after this (more
        imports, say); a failure there is ignored. False when ``fn`` does not pickle or the server is gone."""
        return self._send(b"p", (fn, (), {}))

    def _send(self, kind: bytes, job: tuple, w: int = -1) -> bool:
        """Send a job (or a preparation, without ``w``): pickled into a memory file, whose descriptor travels
        with ``w`` over the socket, so that sending never waits for the server (busy preparing, say).
        Closes ``w`` (this process's copy) in any case."""
        fd = -1
        try:
            if self._sock is None:
                return False
            try:
                data = pickle.dumps(job, protocol=pickle.HIGHEST_PROTOCOL)
            except Exception:  # noqa: BLE001 - a lambda, a local function, an open file: not for the server
                return False
            fd = os.memfd_create("mdsr-job", os.MFD_CLOEXEC)
            try:
                write_all(fd, data)
                socket.send_fds(self._sock, [kind], [fd] + ([w] if w >= 0 else []))
            except OSError:  # the server is gone
                self.kill()
                return False
            self._used = self._used or kind == b"j"
            return True
        finally:
            for d in (fd, w):
                if d >= 0:
                    os.close(d)

    def close(self, timeout: float = 2.0) -> None:
        """End the server once every job it forked has ended: it collects them (their CPU time then counts
        as the caller's children's, as with jobs forked directly) and exits; killed after ``timeout``
        seconds (at once if it was never sent anything). Jobs still waiting in it are dropped (their pipes
        end without a pid): close it when every job sent has been collected."""
        if self._sock is None:
            return
        if not self._used:
            self.kill()
            return
        self._forget()
        deadline = time.monotonic() + timeout
        try:
            while (done := reap(self.pid, block=False)) is None:
                if time.monotonic() > deadline:
                    break
                time.sleep(0.005)
            else:
                self.returncode = done[0]
        finally:  # past the timeout, or interrupted while waiting
            if self.returncode is None:
                send_signal(self.pid, signal.SIGKILL)
                self.returncode = reap(self.pid, block=True)[0]

    def check(self) -> bool:
        """Whether the server still runs; a server found dead is forgotten (:attr:`alive` False)."""
        if self._sock is not None and (done := reap(self.pid, block=False)) is not None:
            self._forget()
            self.returncode = done[0]
        return self.alive

    def _forget(self) -> None:
        """Close this end of the socket: no job is sent any more (:attr:`alive` False)."""
        self._sock.close()
        self._sock = None

    def kill(self) -> None:
        """End the server at once (the jobs it has not forked yet are dropped, those it forked are
        interrupted)."""
        if self._sock is None:
            return
        self._forget()
        send_signal(self.pid, signal.SIGKILL)
        self.returncode = reap(self.pid, block=True)[0]


#: the servers :func:`serving` has started, innermost last
_SERVING: list[ForkServer] = []
#: the servers of this process with their sockets open
_LIVE: weakref.WeakSet[ForkServer] = weakref.WeakSet()


def _forget_servers() -> None:  # pragma: no cover - runs in every forked child
    """In a forked child (a job, another server): close its copies of this process's servers' sockets. A
    copy left open would keep a server from seeing its caller close the socket; and the servers are not
    the child's to use."""
    for server in list(_LIVE):
        if server.alive:
            server._forget()
    _LIVE.clear()


if hasattr(os, "register_at_fork"):
    os.register_at_fork(after_in_child=_forget_servers)


def shared_server() -> ForkServer | None:
    """The server of the innermost :func:`serving` block, if it is alive."""
    return _SERVING[-1] if _SERVING and _SERVING[-1].alive else None


@contextlib.contextmanager
def serving(prepare: Callable[[], Any] | None = None, jobs: int | None = 3):
    """Within the block, every ``BackgroundWriter(server=True)`` forks its jobs from one
    :class:`ForkServer`, started now with ``prepare`` and ``jobs``: a command starts it before its slow start (imports,
    building scenes), and several scenes share its warm-up. Yields the server; at the end closes it (after
    an exception: kills it)."""
    server = ForkServer(prepare, jobs)
    _SERVING.append(server)
    try:
        yield server
    except BaseException:
        _SERVING.remove(server)
        server.kill()
        raise
    _SERVING.remove(server)
    server.close()


class JobNotLoadable(Exception):
    """A served job that the server's process could not unpickle (say, a function of a module the caller
    imported after the server started): the caller forks it itself."""


def load_job(fd: int):  # pragma: no cover - runs in a ForkServer's child
    """Unpickle the job in memory file ``fd`` and run it."""
    try:
        fn, args, kwargs = _unpickle_file(fd)
    except Exception as exc:  # noqa: BLE001 - any failure to load goes back as JobNotLoadable
        raise JobNotLoadable(f"{type(exc).__name__}: {exc}") from None
    return fn(*args, **kwargs)


def _unpickle_file(fd: int):  # pragma: no cover - runs in a ForkServer or its child
    """The object pickled in memory file ``fd`` (closed)."""
    try:
        os.lseek(fd, 0, os.SEEK_SET)
        chunks: list = []
        read_all(fd, chunks)
    finally:
        os.close(fd)
    return pickle.loads(b"".join(chunks))


def _serve(sock: socket.socket, prepare, parent: int, limit: int | None) -> None:  # pragma: no cover
    """The server's life: prepare, then fork the jobs received, at most ``limit`` at a time (the others
    wait here, in order), until the caller closes the socket (or dies, and the kernel kills us)."""
    die_with_parent(parent)
    # Ctrl-C (the terminal's, to the whole process group) ends the queue: no job waiting here starts
    # after it, even while the caller is deep in a solve that delays its own KeyboardInterrupt; the server
    # itself goes on until the caller's stop() kills it
    interrupted: list = []
    signal.signal(signal.SIGINT, lambda *_: interrupted.append(True))
    signal.pthread_sigmask(signal.SIG_SETMASK, set())
    if prepare is not None:
        _prepare_frozen(prepare)
    # an ended child wakes the loop below through this pipe; set after prepare, whose subprocesses wait
    # for their own children
    wake_r, wake_w = os.pipe()
    os.set_blocking(wake_r, False)
    os.set_blocking(wake_w, False)
    signal.set_wakeup_fd(wake_w)
    signal.signal(signal.SIGCHLD, lambda *_: None)
    gc.freeze()  # the jobs' collections leave the server's heap alone (and its pages shared)
    me = os.getpid()
    running: set[int] = set()
    waiting: collections.deque = collections.deque()
    poll = select.poll()
    poll.register(sock.fileno(), select.POLLIN)
    poll.register(wake_r, select.POLLIN)
    while True:
        _collect_ended(running)
        if interrupted:
            while waiting:  # pid 0 in its pipe: the caller knows the job was dropped by the interrupt
                _drop(*waiting.popleft(), interrupted=True)
        while waiting and (limit is None or len(running) < limit):
            job, w = waiting.popleft()
            pid = -1  # not forked: the caller reads the end of a pipe without a pid, and runs the job itself
            if threading.active_count() == 1:  # a thread a preparation started would make a fork unsafe
                try:
                    pid = fork_quietly()  # as the caller's own forks: flushed, no warning of OpenBLAS's threads
                except OSError:
                    pass
            if pid == 0:
                try:
                    signal.set_wakeup_fd(-1)
                    for fd in (sock.fileno(), wake_r, wake_w):
                        os.close(fd)
                    signal.signal(signal.SIGCHLD, signal.SIG_DFL)
                    for other_job, other_w in waiting:
                        os.close(other_job)
                        os.close(other_w)
                    child_main(w, load_job, (job,), {}, me, set(), served=True)
                finally:
                    os._exit(1)
            os.close(job)
            os.close(w)
            if pid > 0:
                running.add(pid)
        ready = {fd for fd, _ in poll.poll()}
        if wake_r in ready:
            try:
                while os.read(wake_r, 512):
                    pass
            except BlockingIOError:
                pass
        if sock.fileno() not in ready:
            continue
        try:
            msg, fds, _flags, _addr = socket.recv_fds(sock, 1, 2)
        except OSError:
            msg, fds = b"", []
        if not msg:  # the caller closed its end: the jobs not started are dropped (their pipes end)
            while waiting:
                _drop(*waiting.popleft(), interrupted=False)
            break
        for fd in fds:  # received descriptors are inheritable: a job's subprocesses must not hold them
            os.set_inheritable(fd, False)
        if msg == b"p" and len(fds) == 1:
            try:
                fn, args, kwargs = _unpickle_file(fds[0])
            except Exception:  # noqa: BLE001 - as with prepare
                pass
            else:  # (a preparation that is not callable fails inside, and is ignored too)
                _prepare_frozen(lambda: fn(*args, **kwargs))
        elif msg == b"j" and len(fds) == 2:
            if interrupted:
                _drop(fds[0], fds[1], interrupted=True)
            else:
                waiting.append((fds[0], fds[1]))
        else:
            for fd in fds:
                os.close(fd)
    signal.set_wakeup_fd(-1)
    signal.signal(signal.SIGCHLD, signal.SIG_DFL)
    while True:  # the last jobs: collected before we go, so that the caller's accounts have them
        try:
            os.wait()
        except ChildProcessError:
            break
    os._exit(0)


def _prepare_frozen(fn: Callable[[], Any]) -> None:  # pragma: no cover - in the server
    """Call a preparation with the garbage collector paused, then freeze what it made (``gc.freeze``); a
    failure is ignored (the jobs then do the work themselves).

    A warm-up imports modules: some 100,000 objects, all living as long as the server, which the
    collections during the imports traversed again and again (0.15-0.18 s of a 1.0-1.5 s warm-up in
    ``mdsr run gecko``, timed with ``gc.callbacks``). Frozen, they are left alone by the server's later
    collections and by its children's, which would otherwise write to them and so copy their pages. A
    preparation leaves next to no garbage behind (a case's prototype: 8 unreachable objects of 2,000)."""
    was = gc.isenabled()
    gc.disable()
    try:
        fn()
    except Exception:  # noqa: BLE001 - a preparation that fails only leaves the jobs to do its work
        pass
    finally:
        gc.freeze()
        if was:
            gc.enable()


def _drop(job: int, w: int, interrupted: bool) -> None:  # pragma: no cover - in the server
    """Drop a job that waits in the server: its pipe ends, after pid 0 when it was dropped by Ctrl-C."""
    try:
        if interrupted:
            os.write(w, bytes(8))
    except OSError:  # the caller has stopped reading
        pass
    finally:
        os.close(job)
        os.close(w)


def _collect_ended(running: set) -> None:  # pragma: no cover - in the server
    """Collect the server's ended children (their CPU time then counts, and no zombie is left)."""
    while running:
        try:
            pid, _status = os.waitpid(-1, os.WNOHANG)
        except ChildProcessError:
            running.clear()
            return
        if pid == 0:
            return
        running.discard(pid)
