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
    from . import author; author.add_cli(sub)  # noqa: E702


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(prog="mdsr", description="Muscle-driven soft robot design toolkit")
    sub = parser.add_subparsers(dest="command", required=True)
    _register_all(sub)
    args = parser.parse_args(argv)
    try:
        return int(args.func(args) or 0)
    except (ValueError, TypeError, FileNotFoundError) as exc:
        print(f"mdsr {args.command}: error: {exc}", file=sys.stderr)
        return 2


if __name__ == "__main__":  # pragma: no cover
    sys.exit(main())
