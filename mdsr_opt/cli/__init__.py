"""The ``mdsr`` command line: ``main`` runs it; one module per command group (``run``, ``study``,
``photos``, ``demo``), registered in :mod:`mdsr_opt.cli.main`."""

from __future__ import annotations

from .main import build_parser, configure_logging, console_main, main

__all__ = ["build_parser", "configure_logging", "console_main", "main"]
