"""``python -m mdsr_opt`` runs the ``mdsr`` command (useful where the script is not on PATH)."""

import sys

from .cli.main import console_main

sys.exit(console_main())
