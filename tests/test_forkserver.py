"""The jobs' server (mdsr_opt.core.forkserver.ForkServer): a process forked early that warms up beside the
caller and forks each job it is sent (pickled).

Every test states what it expects both where this machine may fork and where it may not (the jobs then run
in this process): nothing is skipped.
"""

from __future__ import annotations

import functools
import os
import signal
import subprocess
import sys
import textwrap
import time
from pathlib import Path

import pytest

from mdsr_opt.core.background import BackgroundWriter, fork_is_safe
from mdsr_opt.core.forkserver import ForkServer, serving

ROOT = Path(__file__).resolve().parents[1]

#: set by _remember in the process that calls it
_MARK: list = []


@pytest.fixture
def forks():
    return fork_is_safe()


def _remember(value):
    _MARK.append(value)


def _where(*_):
    """The job's process, its parent and what _remember has left there."""
    return os.getpid(), os.getppid(), list(_MARK)


def _wait_for(path, seconds=20.0):
    """A prepare that waits for the caller to create ``path`` (which it can do only if it goes on)."""
    t0 = time.monotonic()
    while not Path(path).exists():
        if time.monotonic() - t0 > seconds:
            _MARK.append("timed out")
            return
        time.sleep(0.01)
    _MARK.append("saw it")


def _spin(seconds):
    t0 = time.process_time()
    while time.process_time() - t0 < seconds:
        pass
    return seconds


def _fail():
    raise RuntimeError("the job failed on purpose")


def _late_write(path, seconds):
    time.sleep(seconds)
    Path(path).write_text("written")
    return "done"


def _alive(pid: int) -> bool:
    try:
        status = Path(f"/proc/{pid}/status").read_text()
    except OSError:
        return False
    return "zombie" not in status


def test_served_jobs_start_from_the_server_which_prepared_them_not_from_the_caller(forks):
    got = []
    with BackgroundWriter(prepare=functools.partial(_remember, "prepared"), server=True) as bg:
        server = bg._server if forks else None  # noqa: SLF001 - the test looks at whom the jobs came from
        bg.submit(_where, on_done=got.append)
        bg.submit(_where, on_done=got.append)
    assert _MARK == []  # prepare never ran here
    if not forks:  # no server where a fork is unsafe: the jobs ran here, unprepared
        assert got == [(os.getpid(), os.getppid(), [])] * 2
        return
    for pid, ppid, mark in got:
        assert ppid == server.pid != os.getpid() and pid != server.pid
        assert mark == ["prepared"]  # the server's warm memory
    assert not _alive(server.pid)  # the writer's own server ends with the writer


def test_the_caller_goes_on_while_the_server_prepares(tmp_path, forks):
    """The server's preparation runs beside the caller: here it waits for a file the caller writes only
    after its submit has returned (a caller that waited for the preparation would make it time out)."""
    go = tmp_path / "go"
    got = []
    with BackgroundWriter(prepare=functools.partial(_wait_for, go), server=True) as bg:
        bg.submit(_where, on_done=got.append)
        go.write_text("")
    if forks:
        assert got[0][2] == ["saw it"]
    else:  # no server: nothing was prepared, the job ran here
        assert got == [(os.getpid(), os.getppid(), [])]


def test_a_job_that_does_not_pickle_is_forked_from_the_caller(forks):
    got = []
    with BackgroundWriter(server=True) as bg:
        bg.submit(lambda: (os.getpid(), os.getppid()), on_done=got.append)
    assert len(got) == 1
    assert (got[0][1] == os.getpid()) == forks  # a child of this process (or this process itself)


def test_a_job_the_server_cannot_load_is_forked_from_the_caller(tmp_path, forks, monkeypatch):
    """A function of a module imported after the server started (here from a folder only the caller's
    sys.path has) cannot be unpickled there: the caller runs it in its own child, with the same result."""
    with serving() as server:
        (tmp_path / "late_module_for_forkserver.py").write_text(
            "import os\ndef where():\n    return os.getpid(), os.getppid()\n")
        monkeypatch.syspath_prepend(str(tmp_path))
        import late_module_for_forkserver as late

        got = []
        with BackgroundWriter(server=True) as bg:
            bg.submit(late.where, on_done=got.append)
        assert len(got) == 1
        if forks:
            assert got[0][1] == os.getpid() and server.alive  # forked here; the server goes on serving


def test_a_served_job_reports_its_cpu_time(forks):
    with BackgroundWriter(server=True) as bg:
        bg.submit(_spin, 0.2)
    if not forks:
        assert bg.job_cpu == []
        return
    (name, cpu), = bg.job_cpu
    assert name == "_spin" and 0.2 <= cpu < 2.0


def test_a_served_jobs_failure_is_raised_and_stops_the_others(tmp_path, forks):
    late = tmp_path / "late.txt"
    with pytest.raises(RuntimeError, match="failed on purpose") as info:
        with BackgroundWriter(server=True, grace=5.0) as bg:
            bg.submit(_late_write, late, 3.0)
            bg.submit(_fail)
    if forks:
        assert "in the background job _fail" in "".join(getattr(info.value, "__notes__", []))
        time.sleep(3.5)
        assert not late.exists()  # the slow job was stopped, not left writing
    else:  # run here one after the other: the slow job wrote before the failing one ran
        assert late.read_text() == "written"


def test_a_lost_server_leaves_the_jobs_to_the_caller(forks):
    got = []
    with BackgroundWriter(server=True) as bg:
        if forks:
            os.kill(bg._server.pid, signal.SIGKILL)  # noqa: SLF001 - the server dies under the writer
            time.sleep(0.2)
        bg.submit(_where, on_done=got.append)
    assert len(got) == 1 and (got[0][1] == os.getpid()) == forks


def test_serving_shares_one_server_and_its_preparations_then_ends_it(forks):
    got = []
    with serving(functools.partial(_remember, "at start")) as server:
        assert server.alive == forks
        for k in range(2):
            with BackgroundWriter(prepare=functools.partial(_remember, f"writer {k}"), server=True) as bg:
                bg.submit(_where, on_done=got.append)
        assert _MARK == []
    if not forks:
        assert [g[2] for g in got] == [[], []]
        return
    assert {g[1] for g in got} == {server.pid}  # both writers used the one server
    assert got[0][2] == ["at start", "writer 0"] and got[1][2] == ["at start", "writer 0", "writer 1"]
    time.sleep(0.1)
    assert not server.alive and not _alive(server.pid)


def test_a_writers_preparation_reaches_the_jobs_submitted_after_it(forks):
    """BackgroundWriter.prepare runs in the server between the jobs sent before and after it; without a
    server it does nothing and says so."""
    got = {}
    with serving() as server:
        with BackgroundWriter(server=True) as bg:
            bg.submit(_where, on_done=functools.partial(got.__setitem__, "before"))
            assert bg.prepare(functools.partial(_remember, "prepared")) == forks
            assert bg.prepare(lambda: None) is False  # does not pickle: not sent
            bg.submit(_where, on_done=functools.partial(got.__setitem__, "after"))  # jobs end in any order
        assert _MARK == []  # not in this process
    if forks:
        assert {g[1] for g in got.values()} == {server.pid}
        assert got["before"][2] == [] and got["after"][2] == ["prepared"]
    with BackgroundWriter(server=False) as bg:
        assert bg.prepare(functools.partial(_remember, "here")) is False
    assert _MARK == []


def _remember_gc(tag):
    """A preparation that notes whether the collector runs while it does, and leaves an object behind."""
    import gc

    _MARK.append((tag, gc.isenabled()))
    _KEPT.append([tag])  # a tracked object made by the preparation


_KEPT: list = []


def _gc_state(*_):
    """The job's view: the preparations' notes, whether the collector runs, whether what they made is frozen
    (gc.get_objects() leaves frozen objects out)."""
    import gc

    return list(_MARK), gc.isenabled(), [any(o is k for o in gc.get_objects()) for k in _KEPT]


def test_preparations_run_with_the_collector_paused_and_what_they_made_frozen(forks):
    """The server's warm-up and each preparation run with the collector paused (their imports' collections
    were 0.15-0.18 s of a warm-up); what they made is frozen, and the jobs run with the collector on."""
    got = []
    with serving(functools.partial(_remember_gc, "warm-up")):
        with BackgroundWriter(server=True) as bg:
            bg.prepare(functools.partial(_remember_gc, "message"))
            bg.submit(_gc_state, on_done=got.append)
    assert _MARK == [] and _KEPT == []  # neither ran here
    if not forks:  # no server: the job ran here, unprepared
        assert got == [([], True, [])]
        return
    marks, enabled, tracked = got[0]
    assert marks == [("warm-up", False), ("message", False)] and enabled is True
    assert tracked == [False, False]  # frozen: out of the collector's lists


def test_a_preparation_that_fails_or_is_not_callable_leaves_the_server_serving(forks):
    got = []
    with serving() as server:
        with BackgroundWriter(server=True) as bg:
            bg.prepare(None)  # pickles, but cannot be called: ignored there, as a failing one is
            bg.prepare(_fail)
            bg.submit(_where, on_done=got.append)
        if forks:
            assert server.check() and got[0][1] == server.pid  # served by the server, still alive
    assert len(got) == 1


def test_spawn_refuses_what_does_not_pickle_and_a_dead_server():
    server = ForkServer()
    try:
        if not server.alive:
            assert server.spawn(_where) is None
            return
        assert server.spawn(lambda: 1) is None
        assert server.prepare(lambda: 1) is False
        server.kill()
        assert server.spawn(_where) is None and not _alive(server.pid)
    finally:
        server.kill()


def test_a_killed_caller_takes_its_server_and_the_served_jobs_with_it(tmp_path):
    """A run killed outright (SIGKILL: no handler runs) must leave nothing writing: the server dies with it
    and the jobs it forked are interrupted."""
    late = tmp_path / "late.txt"
    script = textwrap.dedent(f"""
        import os, sys, time
        sys.path.insert(0, {str(ROOT)!r})
        sys.path.insert(0, {str(Path(__file__).parent)!r})
        from mdsr_opt.core.background import BackgroundWriter
        from test_forkserver import _late_write
        bg = BackgroundWriter(server=True)
        bg.__enter__()
        bg.submit(_late_write, {str(late)!r}, 4.0)
        print(bg.background, bg._server.pid if bg._server else 0, flush=True)
        time.sleep(60)
    """)
    proc = subprocess.Popen([sys.executable, "-c", script], stdout=subprocess.PIPE, text=True)
    try:
        forked, server = proc.stdout.readline().split()
        server = int(server)
        time.sleep(0.5)  # the job has started
        jobs = [int(p) for p in os.listdir("/proc") if p.isdigit() and _parent_of(int(p)) == server]
        proc.kill()
        proc.wait(timeout=10)
    finally:
        if proc.poll() is None:
            proc.kill()
    time.sleep(1.0)
    if forked != "True":  # the job ran in the caller at its submit, before anything could kill it
        assert late.read_text() == "written"
        return
    assert len(jobs) == 1
    assert not _alive(server) and not any(_alive(p) for p in jobs)
    time.sleep(4.0)
    assert not late.exists()


def _parent_of(pid: int) -> int:
    try:
        stat = Path(f"/proc/{pid}/stat").read_text()
    except OSError:
        return -1
    return int(stat.rsplit(")", 1)[1].split()[1])


def _sleep_then(seconds, value):
    time.sleep(seconds)
    return value


def test_a_job_sent_to_a_server_that_dies_before_forking_it_runs_from_the_caller(forks):
    """The server is killed while it prepares, with a job queued: the job never started, so the caller runs
    it itself (and the next ones too), instead of reporting a failure."""
    got = []
    with BackgroundWriter(prepare=functools.partial(time.sleep, 2.0), server=True) as bg:
        bg.submit(_where, on_done=got.append)
        if forks:
            os.kill(bg._server.pid, signal.SIGKILL)  # noqa: SLF001
        bg.submit(_where, on_done=got.append)
    assert len(got) == 2
    assert all(ppid == os.getpid() for _pid, ppid, _mark in got) == forks


def test_the_server_ends_by_itself_when_the_caller_has_other_children(forks):
    """A process forked by the caller later (a job forked directly, here a lambda) must not hold the
    server's socket open: the server sees the end of its input, collects its jobs and exits by itself
    (killed, it would have taken the full timeout first)."""
    got = []
    with serving() as server:
        with BackgroundWriter(server=True) as bg:
            bg.submit(_where, on_done=got.append)
            bg.submit(lambda: _sleep_then(3.0, "slow"), on_done=got.append)  # a direct child, still running
            bg.wait(1)
            t0 = time.monotonic()
    closed_in = time.monotonic() - t0
    assert "slow" in got or not forks
    if forks:
        assert server.returncode == 0  # exited by itself: it was not killed after the timeout
        assert closed_in < 2.0 + 3.0  # (the writer waited for its slow direct child, not the server)


def test_ctrl_c_while_a_job_is_sent_leaves_no_descriptor_open(forks, monkeypatch):
    import socket

    def interrupted(*args, **kwargs):
        raise KeyboardInterrupt

    with BackgroundWriter(server=True) as bg:
        before = len(os.listdir("/proc/self/fd"))
        monkeypatch.setattr(socket, "send_fds", interrupted)
        for _ in range(5):
            with pytest.raises(KeyboardInterrupt) if forks else contextlib_null():
                bg.submit(_where)
        monkeypatch.undo()
        assert len(os.listdir("/proc/self/fd")) == before
        assert bg._jobs == [] or not forks  # noqa: SLF001 - nothing half-recorded


def contextlib_null():
    import contextlib

    return contextlib.nullcontext()


def _ignore_interrupts_and_sleep(path, seconds):
    signal.signal(signal.SIGINT, signal.SIG_IGN)
    time.sleep(seconds)
    Path(path).write_text("written")


def test_a_served_job_that_ignores_the_interrupt_is_killed_after_the_grace(tmp_path, forks):
    late = tmp_path / "late.txt"
    t0 = time.monotonic()
    with pytest.raises(RuntimeError, match="failed on purpose"):
        with BackgroundWriter(server=True, grace=0.5) as bg:
            bg.submit(_ignore_interrupts_and_sleep, late, 30.0 if forks else 0.0)
            bg.submit(_sleep_then, 0.5, None)  # the first has started (and sent its pid) by then
            bg.wait(1)
            bg.submit(_fail)
    if forks:
        assert time.monotonic() - t0 < 15.0  # not the job's 30 s: killed once the grace had passed
        time.sleep(0.5)
        assert not late.exists()


def _spin_in_a_subprocess(seconds):
    code = f"import time\nt = time.process_time()\nwhile time.process_time() - t < {seconds}: pass\n"
    subprocess.run([sys.executable, "-c", code], check=True)


def test_a_served_jobs_cpu_time_includes_what_it_waited_for(forks):
    with BackgroundWriter(server=True) as bg:
        bg.submit(_spin_in_a_subprocess, 0.3)
    if forks:
        (_name, cpu), = bg.job_cpu
        assert cpu >= 0.3


def _interval(seconds, k):
    t0 = time.time()
    time.sleep(seconds)
    return k, t0, time.time()


def test_the_server_runs_at_most_jobs_children_and_submit_never_waits_for_a_slot(forks):
    """Five 0.4 s jobs with a limit of two: submitting them all returns before the first has ended (they
    wait in the server, not in the caller), no more than two ever run at once, and they start in order."""
    got = []
    with BackgroundWriter(server=True, jobs=2) as bg:
        for k in range(5):
            bg.submit(_interval, 0.4, k, on_done=got.append)
        submitted = time.time()
    assert sorted(k for k, _s, _e in got) == list(range(5))
    if not forks:
        return
    got.sort()
    assert submitted < min(end for _k, _start, end in got)
    for k, start, _end in got:
        assert sum(s <= start + 1e-3 and start < e for _k, s, e in got) <= 2  # running at its start
        # in order: when job k starts, all but one of the jobs sent before it have ended
        assert sum(e <= start + 1e-3 for _k, _s, e in got[:k]) >= k - 1


def _write_after(path, seconds):
    time.sleep(seconds)
    Path(path).write_text("written")
    return str(path)


def test_ctrl_c_at_the_server_drops_its_queue_and_stops_the_caller(tmp_path, forks):
    """A Ctrl-C reaches the server too: no job waiting there starts after it, and the caller learns of it
    at its next collection (a KeyboardInterrupt), even if its own interrupt was swallowed (here it gets
    none at all)."""
    if not forks:
        return
    paths = [tmp_path / f"{k}.txt" for k in range(4)]
    with pytest.raises(KeyboardInterrupt, match="dropped by an interrupt"):
        with BackgroundWriter(server=True, jobs=1, grace=5.0) as bg:
            for p in paths:
                bg.submit(_write_after, p, 0.6)
            time.sleep(0.3)  # the first job runs, the others wait in the server
            os.kill(bg._server.pid, signal.SIGINT)  # noqa: SLF001
    time.sleep(1.5)
    assert [p.exists() for p in paths[1:]] == [False] * 3


def test_the_caller_does_not_wait_behind_a_job_run_here_or_the_servers_queue(tmp_path, forks, monkeypatch):
    """A job the server cannot load (run from here instead) and a job that does not pickle (forked from
    here) each take a slot of their own: neither makes submit wait for the jobs queued in the server."""
    if not forks:
        return
    with serving() as server:
        (tmp_path / "late_module_for_forkserver_2.py").write_text(
            "import time\ndef slow():\n    time.sleep(2.0)\n    return 'slow'\n")
        monkeypatch.syspath_prepend(str(tmp_path))
        import late_module_for_forkserver_2 as late

        got, took = [], []
        with BackgroundWriter(server=True, jobs=2) as bg:
            bg.submit(late.slow, on_done=got.append)
            for k in range(6):  # two rounds of three (the server's limit): 1.2 s
                bg.submit(_sleep_then, 0.6, k, on_done=got.append)
            time.sleep(0.3)  # the first has come back as not loadable by now
            for fn in (lambda: "lambda", functools.partial(_sleep_then, 0.1, "after")):
                t0 = time.monotonic()
                bg.submit(fn, on_done=got.append)
                took.append(time.monotonic() - t0)
        assert sorted(map(str, got)) == sorted(["slow", "lambda", "after"] + [str(k) for k in range(6)])
        assert max(took) < 0.8, took  # the queue alone would take 1.2 s, the job run from here 2 s
        assert server.alive


def test_no_more_than_four_times_jobs_wait_in_the_server(forks):
    if not forks:
        return
    outstanding = []
    with BackgroundWriter(server=True, jobs=1) as bg:
        for k in range(10):
            bg.submit(_sleep_then, 0.1, k)
            outstanding.append(len(bg._jobs))  # noqa: SLF001
    assert max(outstanding) <= 4 and bg._jobs == []  # noqa: SLF001
