"""Output folders of a run: one run at a time, never two runs mixed, nothing partial left behind.

A :class:`RunFolder` guards the folder a run writes into (``mdsr run --out DIR``, :func:`~mdsr_opt.scenes.run_scene`):

- **One writer.** The folder is locked (an advisory ``flock`` on ``DIR/.mdsr-lock``, which the operating
  system drops when the process dies, so a crashed run leaves no lock behind that needs clearing). A second
  run into the same folder fails at once with a message naming the first (its process id and command).
- **No mixing.** A folder that already holds files is refused; with ``overwrite=True`` (``--overwrite``) the
  files of an earlier mdsr run there are removed first. Only files that run recorded in its manifest
  ``DIR/.mdsr-run.json`` are ever removed: a folder holding anything else is refused even then.
- **Nothing partial.** Every file is written through a temporary file (:class:`~mdsr_opt.io.atomic_path`);
  when the run stops (an error, Ctrl-C) the temporaries left in the folder are removed, the files already
  complete stay, and the manifest's ``status`` says ``"interrupted"`` or ``"failed"``.

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
mdsr_opt.scenes.rundir.OutputFolderError: --out ... holds an earlier mdsr run (`example`, complete); pass --overwrite ...
"""

from __future__ import annotations

import contextlib
import json
import os
import shutil
import signal
import socket
import sys
import threading
import time
from pathlib import Path
from typing import Iterable

from ..core.errors import InputError

__all__ = ["RunFolder", "OutputFolderError", "FolderBusy", "check_out_path", "LOCK_NAME", "MANIFEST_NAME",
           "remove_temporaries", "noting_interrupts", "check_interrupt"]

#: The lock file inside a run's folder.
LOCK_NAME = ".mdsr-lock"
#: The manifest inside a run's folder: what the run may write (``claims``), its command and status.
MANIFEST_NAME = ".mdsr-run.json"
_MANIFEST_FORMAT = "mdsr_opt.run_folder/1"
_TMP_PREFIX = ".tmp-"  # io.atomic_path's temporaries

#: the lock files this process holds open: a forked child (a figure job) closes its copies at once, so a
#: folder's lock goes with the run's own process, never with a child that outlives it for a moment
_HELD: set[int] = set()


def _close_held_locks() -> None:  # pragma: no cover - runs in forked children
    for fd in list(_HELD):
        try:
            os.close(fd)
        except OSError:
            pass
    _HELD.clear()


if hasattr(os, "register_at_fork"):
    os.register_at_fork(after_in_child=_close_held_locks)


class OutputFolderError(InputError):
    """The output folder cannot be used: empty name, a file, unwritable, or holding other files."""


class FolderBusy(OutputFolderError):
    """Another run holds the output folder's lock."""


_INTERRUPTED = threading.Event()


def _on_sigint(signum, frame):
    _INTERRUPTED.set()
    raise KeyboardInterrupt


@contextlib.contextmanager
def noting_interrupts():
    """Within the block, Ctrl-C (SIGINT) raises ``KeyboardInterrupt`` as usual and is also remembered, so
    that :func:`check_interrupt` raises it again where a C extension swallowed the first one (CasADi turns
    an interrupt inside a solve into a failed solve). Does nothing outside the main thread, or when SIGINT
    is not Python's default handler (e.g. ignored by the parent shell, or handled by the caller)."""
    if threading.current_thread() is not threading.main_thread() or \
            signal.getsignal(signal.SIGINT) is not signal.default_int_handler:
        yield
        return
    _INTERRUPTED.clear()
    signal.signal(signal.SIGINT, _on_sigint)
    try:
        yield
    finally:
        signal.signal(signal.SIGINT, signal.default_int_handler)
        _INTERRUPTED.clear()


def check_interrupt() -> None:
    """Raise ``KeyboardInterrupt`` if Ctrl-C was pressed inside :func:`noting_interrupts` (even if a solver
    swallowed it). Called between the stages of a run."""
    if _INTERRUPTED.is_set():
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


def remove_temporaries(folder) -> list[str]:
    """Remove the temporary files (``.tmp-*``, left by a write that was cut short) under ``folder``."""
    removed = []
    for root, _dirs, files in os.walk(os.fspath(folder)):
        for f in files:
            if f.startswith(_TMP_PREFIX):
                path = os.path.join(root, f)
                try:
                    os.remove(path)
                    removed.append(path)
                except FileNotFoundError:  # pragma: no cover - gone meanwhile
                    pass
    return removed


def _read_manifest(folder: Path) -> dict | None:
    try:
        data = json.loads((folder / MANIFEST_NAME).read_text())
    except (OSError, ValueError):
        return None
    if not isinstance(data, dict) or data.get("format") != _MANIFEST_FORMAT:
        return None
    return data


def _holder(path: Path) -> str:
    try:
        info = json.loads(path.read_text())
        return (f"pid {info.get('pid')} on {info.get('host')}, `{info.get('command', '?')}`, since "
                f"{info.get('started', '?')}")
    except (OSError, ValueError, AttributeError):
        return "process unknown"


class RunFolder:
    """Context manager guarding a run's output folder (see the module docstring).

    Parameters
    ----------
    out : folder (created with its parents if missing).
    overwrite : bool
        Replace an earlier mdsr run's files in ``out`` (only those its manifest lists); without it a
        folder that holds anything is refused.
    command : str
        Recorded in the lock and the manifest (for the message a second run gets).

    Use :meth:`begin` once the run knows what it will write (after its input is checked): it removes the
    earlier run's files and writes the manifest. :meth:`finish` records the final status.
    """

    def __init__(self, out, *, overwrite: bool = False, command: str = ""):
        self.path = check_out_path(out)
        self.overwrite = bool(overwrite)
        self.command = command or " ".join([os.path.basename(sys.argv[0] or "python"), *sys.argv[1:]])
        self._fd: int | None = None
        self._created: list[Path] = []
        self._old: list[str] = []
        self._begun = False
        self._status = "complete"

    # ---------------------------------------------------------------------------------------------- lock
    def _lock(self) -> None:
        import fcntl

        lock = self.path / LOCK_NAME
        for _ in range(20):
            try:
                fd = os.open(lock, os.O_RDWR | os.O_CREAT, 0o644)
            except OSError as exc:
                raise OutputFolderError(f"--out {self.path}: cannot write into it ({exc.strerror})") from None
            try:
                fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
            except OSError:
                os.close(fd)
                raise FolderBusy(f"--out {self.path}: another mdsr run is writing into this folder "
                                 f"({_holder(lock)}); wait for it to finish or choose another --out") from None
            try:  # the file may have been removed (and re-created) by its last holder meanwhile
                same = os.stat(lock).st_ino == os.fstat(fd).st_ino
            except FileNotFoundError:
                same = False
            if same:
                self._fd = fd
                _HELD.add(fd)
                info = {"pid": os.getpid(), "host": socket.gethostname(), "command": self.command,
                        "started": time.strftime("%Y-%m-%d %H:%M:%S")}
                os.ftruncate(fd, 0)
                os.write(fd, json.dumps(info).encode())
                return
            os.close(fd)
        raise FolderBusy(f"--out {self.path}: could not take the folder's lock")  # pragma: no cover

    def _unlock(self) -> None:
        if self._fd is None:
            return
        try:
            os.remove(self.path / LOCK_NAME)  # still holding the lock: the next run re-creates the file
        except FileNotFoundError:  # pragma: no cover
            pass
        _HELD.discard(self._fd)
        os.close(self._fd)
        self._fd = None

    # ---------------------------------------------------------------------------------------------- protocol
    def __enter__(self) -> "RunFolder":
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
            entries = sorted(e for e in os.listdir(self.path) if e != LOCK_NAME)
            if entries:
                old = _read_manifest(self.path)
                if not self.overwrite and old is not None:
                    raise OutputFolderError(
                        f"--out {self.path} holds an earlier mdsr run (`{old.get('command', '?')}`, "
                        f"{old.get('status', '?')}); pass --overwrite to replace it, or choose a new folder")
                if not self.overwrite:
                    shown = ", ".join(map(repr, entries[:3])) + (", ..." if len(entries) > 3 else "")
                    raise OutputFolderError(
                        f"--out {self.path} already holds {len(entries)} "
                        f"{'entry' if len(entries) == 1 else 'entries'} ({shown}); choose a new or empty folder")
                owned = set(old.get("claims", [])) if old else set()
                owned.add(MANIFEST_NAME)
                foreign = [e for e in entries if e not in owned and not e.startswith(_TMP_PREFIX)]
                if foreign:
                    raise OutputFolderError(
                        f"--out {self.path} holds {foreign[0]!r}, which no earlier mdsr run wrote there; "
                        "--overwrite replaces only an earlier run's files: choose a new folder")
                self._old = entries
        except BaseException:
            self._release(clean=True)
            raise
        return self

    def begin(self, claims: Iterable[str]) -> None:
        """Remove the earlier run's files (``overwrite``) and record what this run may write.

        ``claims`` are the names of the entries (files or folders) directly in the folder.
        """
        claims = sorted(set(claims))
        for e in self._old:
            q = self.path / e
            if q.is_dir() and not q.is_symlink():
                shutil.rmtree(q)
            elif q.exists() or q.is_symlink():
                q.unlink()
        self._old = []
        self._manifest = {"format": _MANIFEST_FORMAT, "status": "running", "command": self.command,
                          "pid": os.getpid(), "started": time.strftime("%Y-%m-%d %H:%M:%S"), "claims": claims}
        self._write_manifest()
        self._begun = True

    def finish(self, status: str = "complete") -> None:
        """Record the run's final status (``"complete"``, ``"failed: ..."``) in the manifest."""
        self._status = status

    def _write_manifest(self) -> None:
        from ..body.io import write_json

        write_json(self.path / MANIFEST_NAME, self._manifest)

    def _release(self, clean: bool) -> None:
        remove_temporaries(self.path)
        self._unlock()
        if clean and not self._begun:  # nothing of this run was written: leave no folder it made
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
                self._manifest.update(status=status, finished=time.strftime("%Y-%m-%d %H:%M:%S"))
                self._write_manifest()
        finally:
            self._release(clean=True)
        return False
