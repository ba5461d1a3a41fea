"""The ``mdsr`` command. Subcommands are registered by the modules that own them.

Global options: ``--version`` (before the subcommand); ``-v`` (more detail: ``-vv`` for debug output of the
library's loggers) and ``-q`` (warnings, errors and results only: no progress lines or bar), before or after
the subcommand, with one meaning in both places. Library modules report through
``logging.getLogger(__name__)``; this module is the only place that configures logging.

Exit codes: 0 success; 1 the command ran but something it checked failed (a solve, a case), or a bug;
2 bad input; 130 Ctrl-C. Bad input is told from a bug by design (:mod:`mdsr_opt.core.errors`), not by
the exception's built-in type: each command checks its arguments and loads its scenes inside
:func:`~mdsr_opt.core.errors.checking_input` before any work, and the public functions it then calls
check their own doors so too (or raise :class:`~mdsr_opt.core.errors.InputError` for bad input found
later, e.g. an unusable output folder); those errors and ``OSError`` are one line with exit code 2. Any
other exception, e.g. a ``TypeError`` or ``ValueError`` from deep inside a solve, is a bug: its traceback
is printed, exit code 1.
"""

from __future__ import annotations

import argparse
import contextlib
import importlib
import logging
import os
import signal
import sys
import threading

from .. import __version__


#: the modules that register subcommands (each has ``add_cli(sub)``) and the subcommands each one adds, in
#: the order ``mdsr --help`` lists them. A module that owns a new subcommand adds one entry here.
OWNERS = ((".demo", ("demo",)), (".photos", ("evaluate", "photograph")), (".run", ("list", "run")),
          (".study", ("study",)), ("..author", ("author",)))


def _register(sub, command: str | None = None) -> None:
    """Register the subcommands: all of them, or with ``command`` only its owner's (its module alone is
    imported: ``mdsr run`` then skips the photograph, demo, study and authoring modules)."""
    known = any(command in cmds for _, cmds in OWNERS)
    for module, cmds in OWNERS:
        if not known or command in cmds:
            importlib.import_module(module, __package__).add_cli(sub)


def command_of(argv: list[str]) -> str | None:
    """The subcommand named in ``argv``: its first word, after global options that take no value (``-v``,
    ``-q``, ``-vq``, ``--verbose``, ``--quiet`` or a prefix of one of these two). None when anything else
    comes first (``-h``, ``--version``, ``--``, ``-``, an unknown option): the full parser then answers."""
    for word in argv:
        if not word.startswith("-") or word == "-":
            return None if word == "-" else word
        if word.startswith("--"):  # argparse takes a prefix of one long option: this one or another?
            if len(word) == 2 or [n for n in ("--verbose", "--quiet", "--version") if n.startswith(word)] \
                    not in (["--verbose"], ["--quiet"]):
                return None
        elif not set(word[1:]) <= {"v", "q"}:
            return None
    return None


def build_parser(command: str | None = None) -> argparse.ArgumentParser:
    """The ``mdsr`` argument parser with every subcommand registered (also used by the tests); with
    ``command`` (a subcommand's name) only that subcommand's module registers its subcommands."""
    parser = argparse.ArgumentParser(prog="mdsr", description="Muscle-driven soft robot design toolkit")
    parser.add_argument("--version", action="version", version=f"%(prog)s {__version__}",
                        help="print the package version and exit")
    _verbosity_options(parser, "log")
    sub = parser.add_subparsers(dest="command", required=True, metavar="COMMAND")
    _register(sub, command)
    for subparser in sub.choices.values():  # also after the subcommand (`mdsr run x.toml -v`), same meaning
        _verbosity_options(subparser, "sub")
    return parser


def _verbosity_options(parser: argparse.ArgumentParser, prefix: str) -> None:
    """``-v``/``--verbose`` and ``-q``/``--quiet`` into ``<prefix>_verbose`` and ``<prefix>_quiet``
    (:func:`_run` adds up those of the command and of its subcommand). A subcommand that has an option of
    either name keeps its own."""
    for flags, kwargs in ((("-v", "--verbose"), dict(action="count", default=0, dest=f"{prefix}_verbose",
                                                     help="more detail (-vv: debug messages of the library)")),
                          (("-q", "--quiet"), dict(action="store_true", dest=f"{prefix}_quiet",
                                                   help="only warnings, errors and results: no progress lines "
                                                        "or bar"))):
        try:
            parser.add_argument(*flags, **kwargs)
        except argparse.ArgumentError:
            pass


class _StderrHandler(logging.StreamHandler):
    """A stream handler that writes to whatever ``sys.stderr`` is when a record comes (it may be replaced,
    e.g. by a test's capture, after the handler was made)."""

    def emit(self, record: logging.LogRecord) -> None:
        self.stream = sys.stderr
        super().emit(record)


def configure_logging(verbose: int = 0, quiet: bool = False) -> int:
    """Send the library's log records (logger ``mdsr_opt``) to stderr at the level the flags ask for.

    Default INFO (progress messages), ``quiet`` WARNING, one ``-v`` keeps INFO with logger names, two or more
    DEBUG. Returns the level. Only the command line calls this; a script configures logging itself.
    """
    level = logging.WARNING if quiet else (logging.DEBUG if verbose >= 2 else logging.INFO)
    logger = logging.getLogger("mdsr_opt")
    for h in list(logger.handlers):
        if getattr(h, "_mdsr_cli", False):
            logger.removeHandler(h)
    handler = _StderrHandler()
    handler._mdsr_cli = True  # type: ignore[attr-defined]
    fmt = "%(levelname)s %(name)s: %(message)s" if verbose else "%(message)s"
    handler.setFormatter(logging.Formatter(fmt))
    logger.addHandler(handler)
    logger.setLevel(level)
    return level


def one_blas_thread_per_process() -> None:
    """Ask OpenBLAS for one thread in this process and the worker processes it starts, unless the
    environment says otherwise (``OPENBLAS_NUM_THREADS``): read when numpy, scipy and CasADi load their
    copies, so it takes effect only before the first of them is imported (CasADi's bundled copy, which
    threadpoolctl does not see, has no other portable setting). The package's dense products are small
    (sparse factorisations do the work, each under :func:`~mdsr_opt.mechanics.blas.one_blas_thread`
    anyway); an idle second thread per library spins on a core the figure jobs need."""
    os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")


@contextlib.contextmanager
def agg_backend():
    """Within the block, matplotlib's backend is Agg (the command line only writes files; importing
    ``mdsr_opt.plot`` leaves the backend alone). Chosen through ``MPLBACKEND`` while matplotlib is not
    imported yet, so that the command need not import it; the variable is as it was after the block (a
    matplotlib imported within keeps Agg, as ``matplotlib.use`` would have left it)."""
    if "matplotlib" in sys.modules:
        import matplotlib

        matplotlib.use("Agg")
        yield
        return
    before = os.environ.get("MPLBACKEND")
    os.environ["MPLBACKEND"] = "Agg"
    try:
        yield
    finally:
        if before is None:
            os.environ.pop("MPLBACKEND", None)
        else:
            os.environ["MPLBACKEND"] = before


def main(argv: list[str] | None = None) -> int:
    """Run the ``mdsr`` command with ``argv`` (default: ``sys.argv[1:]``); returns the exit code.

    0: success; 1: the command ran but something it checked failed (a solve, a case), or a bug of the package
    (its traceback on stderr); 2: bad input or an unusable file or folder (one line on stderr, nothing
    written); 130: interrupted by Ctrl-C; 143: stopped by SIGTERM.

    Called from a plain script file (``python my_script.py``) or from standard input, ``mdsr run`` works in
    this one process, as with ``--serial``: the worker processes of its pool would run the script again
    (:func:`~mdsr_opt.core.jobs.main_is_plain_script`). The ``mdsr`` program and ``python -m mdsr_opt`` use
    the pool.
    """
    return _main(argv, console=False)


def _main(argv: list[str] | None, console: bool) -> int:
    """:func:`main`; ``console``: run as the ``mdsr`` program (:func:`console_main`), whose workers may start
    from its guarded entry point."""
    argv = sys.argv[1:] if argv is None else list(argv)
    one_blas_thread_per_process()
    # imported after the variable is set: it imports numpy, whose OpenBLAS reads it as it loads
    from ..core.jobs import main_is_plain_script

    return _run(build_parser(command_of(argv)), argv, pool=console or not main_is_plain_script())


def _run(parser, argv: list[str], pool: bool = True) -> int:
    """:func:`main` once its parser is built; ``pool``: whether a command may start worker processes."""
    args = parser.parse_args(argv)
    args.command_line = " ".join(["mdsr", *argv])
    args.pool = pool
    args.log_verbose += getattr(args, "sub_verbose", 0)  # `mdsr -v run ...` is `mdsr run ... -v`
    args.log_quiet = args.quiet = args.log_quiet or getattr(args, "sub_quiet", False)
    configure_logging(args.log_verbose, args.log_quiet)
    from ..core.warnlines import warnings_as_log_lines
    from ..scenes.rundir import interrupt_signal, noting_interrupts, recording_command

    _STOP.update(command=args.command, said=False)
    try:
        with agg_backend(), noting_interrupts(sigterm=True), recording_command(args.command_line), \
                warnings_as_log_lines():
            return int(args.func(args) or 0)
    except KeyboardInterrupt:
        # Ctrl-C or SIGTERM: stop at once with one line (no traceback); the commands' writers have removed
        # their temporary files, the files already complete stay. 128 + the signal, as shells report it.
        term = interrupt_signal() == signal.SIGTERM
        print(_stopped_line(args.command, term), file=sys.stderr)
        _STOP["said"] = "term" if term else "int"
        return 143 if term else 130
    except BrokenPipeError:  # `mdsr list | head`: the reader left; not an error of ours
        import os

        os.dup2(os.open(os.devnull, os.O_WRONLY), sys.stdout.fileno())
        return 0
    except Exception as exc:  # noqa: BLE001 - bad input or an unusable file: one line, 2; a bug: its traceback, 1
        from ..core.errors import exit_report

        code, text = exit_report(f"mdsr {args.command}", exc)
        print(text, file=sys.stderr)
        return code


#: the command :func:`_run` runs now and the one line it said on stopping (``said``: "int", "term" or False)
_STOP: dict = {"command": None, "said": False}


def _stopped_line(command: str, term: bool) -> str:
    return (f"\nmdsr {command}: interrupted ({'SIGTERM' if term else 'Ctrl-C'}); files already complete "
            "are kept")


def _ignore_late_signals() -> None:
    """The program stops on Ctrl-C or SIGTERM: later ones are ignored while it exits. A Ctrl-C that lands
    after the first (pressed twice, or the terminal's one reaching the process while its first interrupt,
    or a worker's, is being handled) would otherwise end the process by the signal at shutdown, exit -2,
    after its one line had said 130."""
    if threading.current_thread() is threading.main_thread():
        signal.signal(signal.SIGINT, signal.SIG_IGN)
        signal.signal(signal.SIGTERM, signal.SIG_IGN)


def console_main() -> int:
    """The ``mdsr`` program (the console script and ``python -m mdsr_opt``): :func:`main` on the process's
    arguments. Returns :func:`main`'s exit code; 130 with one line when Ctrl-C comes before the command
    runs (while its modules import), as it does once the command runs. Once it stops on Ctrl-C or SIGTERM,
    later ones are ignored (:func:`_ignore_late_signals`): it exits with 130 (143), one line said."""
    _STOP.update(command=None, said=False)
    try:
        code = _main(None, console=True)
    except KeyboardInterrupt:  # before the command ran, or a second interrupt while it was stopping
        _ignore_late_signals()
        if not _STOP["said"]:
            from ..scenes.rundir import interrupt_signal

            term = interrupt_signal() == signal.SIGTERM
            print("\nmdsr: interrupted (Ctrl-C) before the command started; nothing written"
                  if _STOP["command"] is None else _stopped_line(_STOP["command"], term), file=sys.stderr)
            return 143 if term else 130
        return 143 if _STOP["said"] == "term" else 130
    if code in (130, 143):
        _ignore_late_signals()
    return code


if __name__ == "__main__":  # pragma: no cover
    sys.exit(console_main())
