"""Output folders of a run or study: one writer at a time, never two outputs mixed, a user's files kept.

A :class:`RunFolder` guards the folder a command writes into (``mdsr run --out DIR``, ``mdsr study --out
DIR``, :func:`~mdsr_opt.scenes.runscene.run_scene`, :func:`~mdsr_opt.studies.study.run_study`):

- **One writer.** The folder is locked (``DIR/.mdsr-lock`` through the ``filelock`` package: an operating
  system lock, which goes with the process however it ends, so a killed run leaves no lock that needs
  clearing; the file is removed when the command ends). A second command into the same folder fails at once with a message naming the first (its
  process id and command, from ``DIR/.mdsr-lock.json``).
- **No mixing.** A folder that already holds files is refused. With ``overwrite=True`` (``--overwrite``)
  the files an earlier mdsr command wrote there are removed first: exactly the files its manifest
  ``DIR/.mdsr-run.json`` lists, and then the folders it made if they are left empty. Nothing else is ever
  removed: a file of yours inside a run's sub-folder stays. A folder holding files but no manifest is
  refused even with ``overwrite``.
- **A killed run is known.** Every file a run completes is noted as it is written
  (:func:`~mdsr_opt.body.io.noting_writes`, ``DIR/.mdsr-written``), and the manifest says ``"running"``
  until the run ends. A manifest that says ``"running"`` in a folder whose lock nobody holds is the record
  of a run that was killed (``kill -9``, a power cut): it is reported as interrupted, and ``overwrite``
  removes the files it had written.
- **Nothing partial.** Every file is written through a temporary file (:class:`~mdsr_opt.body.io.atomic_path`);
  when the run stops (an error, Ctrl-C, SIGTERM) the temporaries it left are removed, the files already
  complete stay, and the manifest's ``status`` says ``"interrupted"`` or ``"failed: ..."``.

Example
-------
>>> import tempfile, os
>>> d = os.path.join(tempfile.mkdtemp(), "run")
>>> with RunFolder(d, command="example") as folder:
...     folder.begin(["result.txt"])
...     _ = open(os.path.join(d, "result.txt"), "w").write("42")
>>> sorted(os.listdir(d))
['.mdsr-run.json', 'result.txt']
>>> RunFolder(d).__enter__()  # doctest: +ELLIPSIS
Traceback (most recent call last):
...
mdsr_opt.scenes.rundir.OutputFolderError: --out ... holds an earlier mdsr output (`example`, complete); ...
"""

from __future__ import annotations

import contextlib
import os
import signal
import socket
import sys
import threading
import time
from pathlib import Path, PurePosixPath
from typing import Iterable

from ..body.io import read_json
from ..core.errors import InputError
from ..core.guards import stop_requested

__all__ = ["RunFolder", "OutputFolderError", "FolderBusy", "Terminated", "check_out_path", "LOCK_NAME",
           "MANIFEST_NAME", "remove_temporaries", "noting_interrupts", "check_interrupt", "interrupt_signal",
           "recording_command"]

#: The lock file inside an output folder while a command writes there (removed when it ends).
LOCK_NAME = ".mdsr-lock"
#: Who holds the lock: process id, host, command and start (removed when the lock is released).
HOLDER_NAME = ".mdsr-lock.json"
#: The manifest inside an output folder: the command, its status and the files (and folders) it wrote.
MANIFEST_NAME = ".mdsr-run.json"
#: The files a command has completed so far, one per line (merged into the manifest when it ends).
JOURNAL_NAME = ".mdsr-written"
_OWN = (LOCK_NAME, HOLDER_NAME, MANIFEST_NAME, JOURNAL_NAME)
_MANIFEST_FORMAT = "mdsr_opt.run_folder/2"
_FORMAT_1 = "mdsr_opt.run_folder/1"  # listed the names directly in the folder, files and folders alike
_TMP_PREFIX = ".tmp-"  # io.atomic_path's temporaries


class OutputFolderError(InputError):
    """The output folder cannot be used: empty name, a file, unwritable, or holding other files."""


class FolderBusy(OutputFolderError):
    """Another command holds the output folder's lock."""


class Terminated(KeyboardInterrupt):
    """SIGTERM arrived within :func:`noting_interrupts`: the command stops as on Ctrl-C."""


_INTERRUPTED = threading.Event()
_SIGNAL: list[int] = []  # the signal that interrupted the command (SIGINT or SIGTERM)
_TAKEN: list[int] = []  # the signals noting_interrupts handles now


def _on_sigint(signum, frame):
    _INTERRUPTED.set()
    _SIGNAL[:] = [signal.SIGINT]
    raise KeyboardInterrupt


def _on_sigterm(signum, frame):
    _INTERRUPTED.set()
    handler = signal.getsignal(signal.SIGINT)
    try:  # inside a solve, its guard (core.guards.interruptible, over ours) records the stop as a Ctrl-C
        if signal.SIGINT in _TAKEN and callable(handler) and handler is not _on_sigint:
            handler(signal.SIGINT, frame)
            if stop_requested():  # recorded inside a CasADi solver: raised when the solver returns
                return
    finally:
        _SIGNAL[:] = [signal.SIGTERM]
    raise Terminated("terminated (SIGTERM)")


@contextlib.contextmanager
def noting_interrupts(sigterm: bool = False):
    """Within the block, Ctrl-C (SIGINT) raises ``KeyboardInterrupt`` as usual, and with ``sigterm`` (the
    ``mdsr`` command) SIGTERM raises :class:`Terminated` (a ``KeyboardInterrupt``) instead of ending the
    process at once; either is also remembered, so that :func:`check_interrupt` raises it again where a C
    extension swallowed the first one (CasADi turns an interrupt inside a solve into a failed solve), and
    :func:`interrupt_signal` tells which it was. Does nothing outside the main thread; a signal whose handler
    is not Python's default (ignored by the parent shell, or handled by the caller) is left alone."""
    if threading.current_thread() is not threading.main_thread():
        yield
        return
    defaults = {signal.SIGINT: signal.default_int_handler}
    if sigterm:
        defaults[signal.SIGTERM] = signal.SIG_DFL
    mine = {signal.SIGINT: _on_sigint, signal.SIGTERM: _on_sigterm}
    taken = [s for s, default in defaults.items() if signal.getsignal(s) is default]
    if not taken:  # within another such block, or the caller's own handlers
        yield
        return
    _INTERRUPTED.clear()
    _SIGNAL.clear()
    for s in taken:
        signal.signal(s, mine[s])
    _TAKEN[:] = taken
    try:
        yield
    finally:
        for s in taken:
            signal.signal(s, defaults[s])
        _TAKEN.clear()
        _INTERRUPTED.clear()


def interrupt_signal() -> int | None:
    """The signal (``signal.SIGINT`` or ``signal.SIGTERM``) that interrupted the last
    :func:`noting_interrupts` block, or None."""
    return _SIGNAL[0] if _SIGNAL else None


def check_interrupt() -> None:
    """Raise ``KeyboardInterrupt`` (:class:`Terminated` after SIGTERM) if a signal arrived inside
    :func:`noting_interrupts` (even if a solver swallowed it). Called between the stages of a run."""
    if _INTERRUPTED.is_set():
        if _SIGNAL and _SIGNAL[0] == signal.SIGTERM:
            raise Terminated("terminated (SIGTERM) during a solve")
        raise KeyboardInterrupt("interrupted (Ctrl-C) during a solve")


def check_out_path(out, what: str = "--out") -> Path:
    """Check an output folder name before any work: not empty, not a file, and creatable/writable.

    Returns the path. Raises :class:`OutputFolderError` (a ``ValueError``) with a one-line message.
    """
    if out is None or not isinstance(out, (str, os.PathLike)):
        raise OutputFolderError(f"{what} must be a folder name, got {out!r}")
    text = os.fspath(out)
    if not str(text).strip():
        raise OutputFolderError(f"{what} is empty: give a folder name (use '.' for the current folder)")
    p = Path(text)
    if p.exists() and not p.is_dir():
        raise OutputFolderError(f"{what} {text} is an existing file, not a folder")
    probe = p
    while not probe.exists():  # the nearest existing ancestor must be a writable folder
        if probe.parent == probe:
            break
        probe = probe.parent
    if probe.exists() and not probe.is_dir():
        raise OutputFolderError(f"{what} {text}: {probe} is a file, not a folder")
    if probe.exists() and not os.access(probe, os.W_OK | os.X_OK):
        raise OutputFolderError(f"{what} {text}: cannot write into {probe} (permission denied)")
    return p


def remove_temporaries(folder, within: Iterable[str] | None = None) -> list[str]:
    """Remove the temporary files (``.tmp-*``, left by a write that was cut short) under ``folder``; with
    ``within`` (names directly in the folder) only those in the folder itself and under those names."""
    removed = []
    folder = os.fspath(folder)
    tops = None if within is None else set(within)
    for root, _dirs, files in os.walk(folder):
        rel = os.path.relpath(root, folder)
        if tops is not None and rel != "." and rel.split(os.sep)[0] not in tops:
            continue
        for f in files:
            if f.startswith(_TMP_PREFIX):
                path = os.path.join(root, f)
                try:
                    os.remove(path)
                    removed.append(path)
                except FileNotFoundError:  # pragma: no cover - gone meanwhile
                    pass
    return removed


# ---------------------------------------------------------------------------------------------- records
def _safe_name(p) -> str | None:
    """``p`` as a path relative to a folder (``a/b.png``) if it cannot point outside it, else None."""
    if not isinstance(p, str) or not p or any(c in p for c in "\\:\0\n"):
        return None
    pp = PurePosixPath(p)
    if pp.is_absolute() or any(part in ("", ".", "..") for part in pp.parts) or p.endswith("/"):
        return None
    if len(pp.parts) == 1 and pp.parts[0] in _OWN:
        return None
    return pp.as_posix()


def _listed(value) -> list[str]:
    """The safe names in a manifest's list (anything else in it, or a value that is no list, is ignored)."""
    return [n for n in (_safe_name(v) for v in (value if isinstance(value, list) else [])) if n]


def _check_claims(claims: Iterable[str]) -> list[str]:
    claims = sorted(set(claims))
    for c in claims:
        if _safe_name(c) is None:
            raise ValueError(f"cannot claim {c!r} in an output folder: not a plain name inside it")
    return claims


def _under(name: str, tops: Iterable[str]) -> bool:
    return any(name == t or name.startswith(t + "/") for t in tops)


def _inside(folder: Path, q: Path) -> bool:
    """Whether ``q``'s parent is ``folder`` or lies in it, symbolic links resolved."""
    root, parent = os.path.realpath(folder), os.path.realpath(q.parent)
    return parent == root or parent.startswith(root + os.sep)


def _remove_empty_folders(folder: Path, names: Iterable[str]) -> None:
    """Remove the folders ``names`` (relative to ``folder``) that are empty, deepest first, so a folder whose
    sub-folders all go goes too; nothing reached through a symbolic link, nothing outside ``folder``."""
    for name in sorted(names, key=lambda n: -n.count("/")):
        q = folder / name
        if _inside(folder, q) and q.is_dir() and not q.is_symlink():
            try:
                q.rmdir()
            except OSError:  # not empty: it holds files that are not this command's
                pass


def _journal(folder: Path) -> list[str]:
    try:
        text = (folder / JOURNAL_NAME).read_bytes()
    except OSError:
        return []
    return [n for n in (os.fsdecode(line) for line in text.splitlines()) if _safe_name(n)]


class _Earlier:
    """What an earlier command left in a folder, from its manifest (and journal)."""

    def __init__(self, data: dict, folder: Path):
        self.command = str(data.get("command", "?"))
        self.started = str(data.get("started", "?"))
        status = str(data.get("status", "?"))
        # we hold the lock: a manifest still saying "running" is a run whose process was killed
        self.killed = status == "running"
        self.status = "interrupted" if self.killed else status
        self.problem = ""
        names = _listed(data.get("files" if data["format"] == _MANIFEST_FORMAT else "claims"))
        if data["format"] == _FORMAT_1:
            folders = [n for n in names if (folder / n).is_dir() and not (folder / n).is_symlink()]
            if folders:
                shown = ", ".join(map(repr, folders[:3])) + (", ..." if len(folders) > 3 else "")
                self.problem = (f"its manifest, written by an earlier mdsr version, names the folder(s) {shown} "
                                "but not the files in them")
            self.claims = names
            self.files, self.dirs = [n for n in names if n not in folders], []
        else:
            self.claims = _listed(data.get("claims"))
            self.files = sorted(set(names) | set(_journal(folder)))
            dirs = set(_listed(data.get("dirs")))
            if self.killed:  # it never listed its folders: those of its files that were not there before it,
                # and the claimed folders it had made before their first file was complete (only empty ones go)
                kept = set(_listed(data.get("dirs_before"))) | {""}
                dirs |= {str(PurePosixPath(f).parents[i]) for f in self.files
                         for i in range(len(PurePosixPath(f).parts) - 1)} - kept
                dirs |= {c for c in self.claims if (folder / c).is_dir() and not (folder / c).is_symlink()} - kept
            self.dirs = sorted(d for d in dirs if _under(d, self.claims))

    def describe(self) -> str:
        if self.killed:
            return (f"the files of an interrupted mdsr command (`{self.command}`, started {self.started}, "
                    "which stopped without finishing)")
        return f"an earlier mdsr output (`{self.command}`, {self.status})"


def _read_earlier(folder: Path) -> _Earlier | None:
    try:
        data = read_json(folder / MANIFEST_NAME)
    except (OSError, ValueError):  # unreadable, not JSON, or nested too deeply: no manifest of ours
        return None
    if not isinstance(data, dict) or data.get("format") not in (_MANIFEST_FORMAT, _FORMAT_1):
        return None
    return _Earlier(data, folder)


def _holder(path: Path) -> str:
    try:
        info = read_json(path)
        return (f"pid {info.get('pid')} on {info.get('host')}, `{info.get('command', '?')}`, since "
                f"{info.get('started', '?')}")
    except (OSError, ValueError, AttributeError):
        return "process unknown"


def _identity(st: os.stat_result) -> tuple:
    return st.st_ino, st.st_mtime_ns, st.st_size


def _walk(folder: Path) -> tuple[dict[str, tuple], set[str]]:
    """The files (with their identity) and the folders under ``folder``, by relative name; the folder's
    own records and temporaries left out; symbolic links are not followed."""
    files, dirs = {}, set()
    for root, subdirs, names in os.walk(folder):
        rel = Path(root).relative_to(folder).as_posix()
        prefix = "" if rel == "." else rel + "/"
        for d in subdirs:
            dirs.add(prefix + d)
        for n in names:
            if n.startswith(_TMP_PREFIX) or (not prefix and n in _OWN):
                continue
            try:
                files[prefix + n] = _identity(os.lstat(os.path.join(root, n)))
            except OSError:  # pragma: no cover - gone meanwhile
                pass
    return files, dirs


_COMMANDS: list[str] = []  # recording_command's stack


@contextlib.contextmanager
def recording_command(text: str):
    """Within the block, an output folder records ``text`` as the command that wrote it (unless given
    one): ``mdsr`` records its command line as typed, whichever function opens the folder."""
    _COMMANDS.append(str(text))
    try:
        yield
    finally:
        _COMMANDS.pop()


def _command_line() -> str:
    """The command that opens an output folder: :func:`recording_command`'s, else this process's command
    line as typed (``mdsr study quick ...``, ``python -m mdsr_opt ...``, ``script.py ...``)."""
    if _COMMANDS:
        return _COMMANDS[-1]
    first = sys.argv[0] if sys.argv and sys.argv[0] else "python"
    if os.path.basename(first) == "__main__.py":
        first = "python -m " + os.path.basename(os.path.dirname(os.path.abspath(first)))
    else:
        first = os.path.basename(first)
    return " ".join([first, *sys.argv[1:]])


# ---------------------------------------------------------------------------------------------- the folder
class RunFolder:
    """Context manager guarding an output folder (see the module docstring).

    Parameters
    ----------
    out : folder (created with its parents if missing).
    overwrite : bool
        Replace an earlier mdsr command's files in ``out`` (only those its manifest lists); without it a
        folder that holds anything is refused.
    command : str
        Recorded with the lock and in the manifest (for the messages a later command gets).
    claims : names, optional
        What the command will write, when known already: checked on entry as :meth:`begin` checks them, so
        that a command that writes only at its end (a study) is refused before its work.

    Use :meth:`begin` once the command knows what it will write (after its input is checked): it removes the
    earlier command's files and writes the manifest. :meth:`finish` records the final status. When the
    block ends, the manifest lists the files the command wrote (and the folders it made).
    """

    def __init__(self, out, *, overwrite: bool = False, command: str = "", claims: Iterable[str] | None = None):
        self.path = check_out_path(out)
        self._early = None if claims is None else _check_claims(claims)
        self.overwrite = bool(overwrite)
        self.command = command or _command_line()
        self._lock_obj = None
        self._lock_was_there = True
        self._noting = None
        self._created: list[Path] = []
        self._earlier: _Earlier | None = None
        self._claims: list[str] = []
        self._before: tuple[dict, set] = ({}, set())
        self._begun = False
        self._status = "complete"

    # ---------------------------------------------------------------------------------------------- lock
    def _lock(self) -> None:
        from filelock import FileLock, Timeout

        from ..body.io import write_json

        lock = FileLock(os.fspath(self.path / LOCK_NAME), timeout=0)
        self._lock_was_there = (self.path / LOCK_NAME).exists()
        try:
            lock.acquire()
            if not (self.path / LOCK_NAME).exists():  # the last holder removed the file we locked: lock anew
                lock.release()
                lock.acquire()
        except Timeout:
            raise FolderBusy(f"--out {self.path}: another mdsr process is writing into this folder "
                             f"({_holder(self.path / HOLDER_NAME)}); wait for it to finish or choose another "
                             "--out") from None
        except OSError as exc:
            raise OutputFolderError(f"--out {self.path}: cannot lock it ({exc.strerror or exc})") from None
        self._lock_obj = lock
        write_json(self.path / HOLDER_NAME, {"pid": os.getpid(), "host": socket.gethostname(),
                                             "command": self.command,
                                             "started": time.strftime("%Y-%m-%d %H:%M:%S")})

    def _unlock(self, forget_file: bool) -> None:
        if self._lock_obj is None:
            return
        for name in (HOLDER_NAME, LOCK_NAME) if forget_file else (HOLDER_NAME,):
            try:  # still holding the lock
                os.remove(self.path / name)
            except OSError:
                pass
        self._lock_obj.release()
        self._lock_obj = None

    # ---------------------------------------------------------------------------------------------- protocol
    def __enter__(self) -> "RunFolder":
        from ..body.io import noting_writes

        missing = []
        p = self.path
        while not p.exists():
            missing.append(p)
            if p.parent == p:
                break
            p = p.parent
        try:
            self.path.mkdir(parents=True, exist_ok=True)
        except OSError as exc:
            raise OutputFolderError(f"--out {self.path}: cannot create it ({exc.strerror})") from None
        self._created = missing
        try:
            self._lock()
            self._noting = noting_writes(self.path, self.path / JOURNAL_NAME)
            self._noting.__enter__()  # processes forked from here on note their files too
            self._check()
        except BaseException:
            self._release()
            raise
        return self

    def _check(self) -> None:
        entries = sorted(e for e in os.listdir(self.path) if e not in (LOCK_NAME, HOLDER_NAME))
        if not entries:
            return
        earlier = _read_earlier(self.path)
        if not self.overwrite:
            if earlier is not None:
                raise OutputFolderError(f"--out {self.path} holds {earlier.describe()}; pass --overwrite to "
                                        "replace it (overwrite=True from Python), or choose a new folder")
            shown = ", ".join(map(repr, entries[:3])) + (", ..." if len(entries) > 3 else "")
            raise OutputFolderError(
                f"--out {self.path} already holds {len(entries)} {'entry' if len(entries) == 1 else 'entries'} "
                f"({shown}); choose a new or empty folder")
        if earlier is None:
            foreign = [e for e in entries if e not in _OWN and not e.startswith(_TMP_PREFIX)]
            if foreign:
                raise OutputFolderError(
                    f"--out {self.path} holds {foreign[0]!r}, which no earlier mdsr command wrote there; "
                    "--overwrite replaces only an earlier command's files: choose a new folder")
        elif earlier.problem:
            raise OutputFolderError(
                f"--out {self.path}: {earlier.problem}, so --overwrite cannot tell its files from yours; remove "
                "them yourself or choose a new folder")
        self._earlier = earlier
        if self._early is not None:
            self._refuse_users_files(self._early)

    def _refuse_users_files(self, claims: list[str]) -> None:
        """Refuse a file directly in the folder that this command would write and that is not the earlier
        command's (a file of the user's)."""
        old_files = set(self._earlier.files) if self._earlier else set()
        for c in claims:
            if c not in old_files and (self.path / c).is_file():
                raise OutputFolderError(
                    f"--out {self.path} holds {c!r}, which no earlier mdsr command wrote there and which this "
                    "command writes; move it or choose a new folder")

    def begin(self, claims: Iterable[str]) -> None:
        """Remove the earlier command's files (``overwrite``) and record what this one may write.

        ``claims`` are the names directly in the folder (files and folders) that this command writes; the
        manifest will list the files it wrote under them.
        """
        claims = _check_claims(claims)
        self._refuse_users_files(claims)
        old = self._earlier
        # the cut-short writes first: a temporary left in a folder of a killed run would keep that folder
        remove_temporaries(self.path, claims + (old.claims if old else []))
        if old is not None:
            self._remove_earlier(old)
        try:  # what a command noted is its own record: a journal left without its manifest says nothing
            os.remove(self.path / JOURNAL_NAME)
        except FileNotFoundError:
            pass
        self._earlier = None
        self._claims = claims
        self._before = _walk(self.path)
        self._manifest = {"format": _MANIFEST_FORMAT, "status": "running", "command": self.command,
                          "pid": os.getpid(), "host": socket.gethostname(),
                          "started": time.strftime("%Y-%m-%d %H:%M:%S"), "claims": claims, "files": [], "dirs": [],
                          "dirs_before": sorted(d for d in self._before[1] if _under(d, claims))}
        self._write_manifest()
        self._begun = True

    def _remove_earlier(self, old: _Earlier) -> None:
        """Remove the files ``old`` lists, then the folders it made that are left empty; nothing that lies
        outside this folder (through a symbolic link) and nothing else."""
        for name in old.files:
            q = self.path / name
            if _inside(self.path, q) and (q.is_symlink() or q.is_file()):
                q.unlink()
        _remove_empty_folders(self.path, old.dirs)

    def finish(self, status: str = "complete") -> None:
        """Record the command's final status (``"complete"``, ``"failed: ..."``) in the manifest."""
        self._status = status

    def _written(self) -> tuple[list[str], list[str]]:
        """The files this command wrote (noted as written, or new or replaced under its claims since
        :meth:`begin`) and the folders it made under its claims."""
        files_before, dirs_before = self._before
        files_now, dirs_now = _walk(self.path)
        noted = {n for n in _journal(self.path) if n in files_now}
        changed = {n for n, ident in files_now.items()
                   if _under(n, self._claims) and files_before.get(n) != ident}
        made = {d for d in dirs_now if _under(d, self._claims) and d not in dirs_before}
        return sorted(noted | changed), sorted(made)

    def _write_manifest(self) -> None:
        from ..body.io import write_json

        write_json(self.path / MANIFEST_NAME, self._manifest)

    def _release(self) -> None:
        if self._noting is not None:
            self._noting.__exit__(None, None, None)
            self._noting = None
        if self._begun:
            remove_temporaries(self.path, self._claims)
        # the lock file goes (removed while still held); a command that wrote nothing also leaves no folder it
        # made (a lock file that was there before, e.g. left by an older version, stays then)
        self._unlock(forget_file=self._begun or not self._lock_was_there)
        if not self._begun:
            for p in self._created:
                try:
                    p.rmdir()
                except OSError:
                    break

    def __exit__(self, exc_type, exc, tb):
        try:
            if self._begun:
                if exc_type is None:
                    status = self._status
                elif issubclass(exc_type, KeyboardInterrupt):
                    status = "interrupted"
                else:
                    status = f"failed: {exc_type.__name__}: {exc}"[:300]
                files, dirs = self._written()
                if exc_type is not None:  # a stopped command leaves no empty folder of its own
                    _remove_empty_folders(self.path, dirs)
                    dirs = [d for d in dirs if (self.path / d).is_dir()]
                self._manifest.update(status=status, finished=time.strftime("%Y-%m-%d %H:%M:%S"), files=files,
                                      dirs=dirs)
                self._write_manifest()
                try:  # the manifest lists them now
                    os.remove(self.path / JOURNAL_NAME)
                except FileNotFoundError:
                    pass
        finally:
            self._release()
        return False
