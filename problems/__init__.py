"""The problem library: one problem-definition script per scene of the paper.

Each module defines ``build(resolution="medium") -> mdsr_opt.Scene`` (a factory the tests import)
and runs the whole pipeline under ``if __name__ == "__main__"``::

    python problems/gecko.py --out out/gecko          # or: mdsr run gecko --out out/gecko

``mdsr_opt.get_problem(name)`` finds these files by path (``mdsr_opt.scenes.library.problems_dir``), so
the registry works without this folder being on ``sys.path``. The folder stays at the top of the source
tree; the wheel ships it inside the package as ``mdsr_opt.problems`` (see ``pyproject.toml``), so an
installed ``mdsr list`` / ``mdsr run NAME`` works from any folder. The package form also lets tests run
from the repository root write ``from problems import gecko``.
"""
