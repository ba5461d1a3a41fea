"""The ``mdsr`` command. Subcommands are registered by the modules that own them."""

from __future__ import annotations

import argparse
import sys


def _register_all(sub) -> None:
    from . import demo

    demo.add_cli(sub)
    # each module that owns a subcommand adds one line here: `from . import X; X.add_cli(sub)`
    from . import evaluate; evaluate.add_cli(sub)  # noqa: E702
    from . import scenes; scenes.add_cli(sub)  # noqa: E702
    from . import study; study.add_cli(sub)  # noqa: E702


def main(argv: list[str] | None = None) -> int:
    """Run the ``mdsr`` command with ``argv`` (default: ``sys.argv[1:]``); returns the exit code.

    0: success; 1: the command ran but something it checked failed (a solve, a case); 2: bad input or an
    unusable file or folder (one line on stderr, nothing written); 130: interrupted by Ctrl-C.
    """
    parser = argparse.ArgumentParser(prog="mdsr", description="Muscle-driven soft robot design toolkit")
    sub = parser.add_subparsers(dest="command", required=True)
    _register_all(sub)
    args = parser.parse_args(argv)
    args.command_line = " ".join(["mdsr", *(sys.argv[1:] if argv is None else argv)])
    from .rundir import noting_interrupts

    try:
        with noting_interrupts():
            return int(args.func(args) or 0)
    except KeyboardInterrupt:
        # Ctrl-C: stop at once with one line (no traceback); the commands' writers have removed their
        # temporary files, the files already complete stay. 130 = 128 + SIGINT, as shells report it.
        print(f"\nmdsr {args.command}: interrupted (Ctrl-C); files already complete are kept", file=sys.stderr)
        return 130
    except (ValueError, TypeError, OSError) as exc:  # bad input, an unusable file or folder: one line
        text = str(exc) if not isinstance(exc, OSError) or not exc.filename else \
            f"{exc.strerror or type(exc).__name__}: {exc.filename}"
        print(f"mdsr {args.command}: error: {text}", file=sys.stderr)
        return 2


if __name__ == "__main__":  # pragma: no cover
    sys.exit(main())
