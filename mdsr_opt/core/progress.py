"""Progress bars for the long commands (``mdsr run``, ``mdsr study``), built on tqdm.

A :class:`Progress` is a tqdm bar with an estimate of the time left, and at the same time the ``log``
callback that the pipeline functions already take (``run_scene(..., log=...)``, ``run_study(..., log=...)``):
every message becomes the bar's current stage, and the functions tell it how much work there is and when a
unit is done through :func:`expect` and :func:`advance`. These two are no-ops for a plain callable such as
``print``, so library code calls them unconditionally and stays free of any terminal handling.

The bar is drawn on stderr only when stderr is a terminal (tqdm's own rule); otherwise, and with a bar when
``verbose`` is set, the messages are printed one per line as before. With ``names`` (``mdsr -v``) each line
starts with its level and the name of the module that said it, as the library's log records do.

Example
-------
>>> import io
>>> out = io.StringIO()
>>> with Progress(2, "demo", enabled=False, stream=out) as log:
...     log("first stage done")
...     advance(log)
>>> out.getvalue()
'first stage done\\n'
>>> log.n, log.total
(1, 2)
"""

from __future__ import annotations

import os
import re
import sys
from typing import Any, TextIO

from .checks import check_int

__all__ = ["Progress", "advance", "expect", "is_loud", "progress_for_cli"]

#: the bar's layout: tqdm's default without the rate (``3.18s/stage``), which leaves room for the current stage
BAR_FORMAT = "{l_bar}{bar}| {n_fmt}/{total_fmt} [{elapsed}<{remaining}{postfix}]"

#: the fewest columns the bar itself keeps (the current stage beside it is shortened to fit the terminal)
MIN_BAR = 10


def _terminal_width() -> int:
    """Columns of the terminal on stderr; 0 when unknown (some pseudo-terminals report a 0 x 0 size)."""
    try:
        return os.get_terminal_size(sys.stderr.fileno()).columns
    except (OSError, ValueError, AttributeError):
        return 0


def advance(log: Any, n: int = 1) -> None:
    """Tell a progress-aware ``log`` callback that ``n`` more units of work are done (else do nothing)."""
    step = getattr(log, "advance", None)
    if callable(step):
        step(n)


def expect(log: Any, n: int) -> None:
    """Tell a progress-aware ``log`` callback that ``n`` more units of work are coming (else do nothing)."""
    more = getattr(log, "expect", None)
    if callable(more):
        more(n)


class Progress:
    """A tqdm progress bar that is also a ``log`` callback.

    Parameters
    ----------
    total : int
        Units of work known at the start (cases, runs); :meth:`expect` adds more.
    desc : str
        The label in front of the bar.
    enabled : bool or None
        Draw the bar: ``None`` (default) when stderr is a terminal, ``False`` never (``-q``, or messages
        only).
    stream : file, optional
        Where messages go (default ``sys.stdout`` at the time of the call); ``None`` drops them.
    verbose : bool
        With a bar, still print every message above it (without, only failures and warnings are printed;
        the rest shows as the bar's current stage).
    unit : str
        tqdm's unit name.
    names : bool
        Start every printed line with ``INFO <module>: `` (``WARNING`` for a warning or a failure), the
        module being the one that called the callback: the format of the log records under ``mdsr -v``.
    quiet : bool
        Print only warnings and failures (``mdsr -q``): a message saying ``FAILED``, or one that starts,
        after its ``[scene case]`` label, with ``warning``, ``error`` or a warning's class name
        (``FabricationWarning: ...``).
    """

    def __init__(self, total: int = 0, desc: str = "", *, enabled: bool | None = None,
                 stream: TextIO | None | str = "stdout", verbose: bool = False, unit: str = "step",
                 names: bool = False, quiet: bool = False) -> None:
        from tqdm import tqdm

        total = check_int(total, "total", 0)
        self._stream = stream
        self.quiet = bool(quiet)
        self.verbose = bool(verbose)
        self.names = bool(names)
        disable = (not sys.stderr.isatty()) if enabled is None else not enabled
        self._bar = tqdm(total=total, desc=desc, unit=unit, disable=disable, file=sys.stderr,
                         **({"dynamic_ncols": True} if _terminal_width() > 0 else {"ncols": 100, "nrows": 24}),
                         leave=True, smoothing=0.1, bar_format=BAR_FORMAT)
        self.total = total
        self.n = 0

    @property
    def active(self) -> bool:
        """True when the bar is drawn."""
        return not self._bar.disable

    def _out(self) -> TextIO | None:
        return sys.stdout if self._stream == "stdout" else (sys.stderr if self._stream == "stderr" else
                                                            self._stream)  # type: ignore[return-value]

    def __call__(self, message: str) -> None:
        """Log one message: the bar's current stage, and a printed line (see ``verbose``)."""
        text = message = str(message)
        out = self._out()
        loud = is_loud(message)
        if self.quiet and not loud:
            return
        if self.names:
            caller = sys._getframe(1).f_globals.get("__name__", "?")
            message = f"{'WARNING' if loud else 'INFO'} {caller}: {message}"
        if not self.active:
            if out is not None:
                print(message, file=out, flush=True)
            return
        first = text.strip().splitlines()[0] if text.strip() else ""
        room = self._postfix_room()
        self._bar.set_postfix_str(first if len(first) <= room else first[:room - 3] + "...", refresh=True)
        if (loud or self.verbose) and out is not None:
            self._bar.write(message, file=out)

    def _postfix_room(self) -> int:
        """How many characters of the current stage fit beside a bar of :data:`MIN_BAR` columns in the
        terminal's width (100 where unknown): at most 48, at least 12."""
        width = _terminal_width() or 100
        digits = len(str(max(self.total, self.n)))
        # "desc: 100%|" + bar + "| n/total [mm:ss<mm:ss, " + stage + "]" (hours take two columns more each)
        fixed = len(self._bar.desc) + 2 + 5 + 2 + 2 * digits + 1 + 1 + 12 + 4 + 2 + 1
        return max(12, min(48, width - fixed - MIN_BAR))

    def advance(self, n: int = 1) -> None:
        """``n`` more units are done."""
        self.n += n
        if self.n > self.total:  # more work than announced: keep the bar honest rather than over 100 %
            self.expect(self.n - self.total)
        self._bar.update(n)

    def expect(self, n: int) -> None:
        """``n`` more units of work are coming."""
        self.total += int(n)
        self._bar.total = self.total
        self._bar.refresh()

    def close(self) -> None:
        """Finish the bar (it stays on screen with the elapsed time)."""
        self._bar.close()

    def __enter__(self) -> "Progress":
        return self

    def __exit__(self, *exc: Any) -> None:
        self.close()


def is_loud(message: str) -> bool:
    """Whether a log message is a warning or a failure (shown under ``-q`` and above a bar): it says
    ``FAILED``, or after its ``[scene case]`` label it starts with ``warning``, ``error`` or the name of a
    warning class (``FabricationWarning: ...``)."""
    message = str(message)
    body = re.sub(r"^\s*\[[^\]]*\]\s*", "", message)
    return ("FAILED" in message or body.lower().startswith(("warning", "error"))
            or re.match(r"[A-Za-z]*Warning\b", body) is not None)


def progress_for_cli(args: Any, total: int, desc: str, *, stream: str = "stdout", unit: str = "step",
                     bar: bool = True) -> Progress:
    """The :class:`Progress` a subcommand uses: off with ``-q``/``--quiet`` (only warnings and failures
    printed), a bar on
    a terminal (unless ``bar=False``), messages printed above it with ``-v`` and each line led by its level
    and module's name (``-v``, ``-vv``)."""
    quiet = bool(getattr(args, "quiet", False) or getattr(args, "log_quiet", False))
    return Progress(total, desc, enabled=False if (quiet or not bar) else None, stream=stream, quiet=quiet,
                    verbose=bool(getattr(args, "log_verbose", 0)), unit=unit,
                    names=bool(getattr(args, "log_verbose", 0)))
