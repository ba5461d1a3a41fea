"""matplotlib for a process that only writes files: imported without the property tables of its docstrings.

Each artist class matplotlib defines writes a table of its settable properties into its ``set`` method's
docstring (and the ``%(Line2D:kwdoc)s``-style substitutions of its plotting functions); building those
tables parses every setter's docstring, a quarter of matplotlib's import (0.2 of 0.8 s here). A process in
which nobody reads a docstring (the figure jobs' server of ``mdsr run``, and the jobs forked from it) can
leave them out: :func:`without_property_docs`.
"""

from __future__ import annotations

import contextlib
import sys

__all__ = ["without_property_docs"]

_NOTE = "(property table left out: this process only writes figure files)"


def _no_table(artist) -> str:
    return _NOTE


@contextlib.contextmanager
def without_property_docs():
    """Within the block, the matplotlib artist classes being defined (imported) get a one-line note where
    their property tables would be (``matplotlib.artist.kwdoc``, swapped for the block); so do, for the rest
    of the process, docstrings that substitute a table made within it (``%(Line2D:kwdoc)s``, kept by
    matplotlib once made). Nothing changes
    when ``matplotlib.artist`` was imported already (its classes have their tables: an interactive user's
    process keeps them). Only docstrings are affected: drawing, setters and their signatures are as they
    were.

    Example
    -------
    >>> with without_property_docs():
    ...     import matplotlib.lines
    """
    if "matplotlib.artist" in sys.modules:
        yield
        return
    import matplotlib.artist as artist

    kwdoc = artist.kwdoc
    artist.kwdoc = _no_table
    try:
        yield
    finally:
        artist.kwdoc = kwdoc
