"""The ``mdsr`` command line: :func:`mdsr_opt.cli.main.main` runs it; one module per command group (``run``,
``study``, ``photos``, ``demo``), registered in :mod:`mdsr_opt.cli.main`."""
