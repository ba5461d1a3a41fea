"""One BLAS thread during a solve: sparse factorisations are not worth two threads fighting over cores.

scipy's SuperLU and numpy's products call OpenBLAS, each its own bundled copy. With several threads on
cores busy with other work, the threads wait for each other, and a large solve takes several times as long
as with one thread.
:func:`one_blas_thread` limits every BLAS library that threadpoolctl finds loaded to one thread for the
duration of a ``with`` block and restores the previous counts afterwards.

CasADi's bundled OpenBLAS (which IPOPT's MUMPS uses) is not a library threadpoolctl knows: it reads its
thread count from ``OPENBLAS_NUM_THREADS`` when it loads, which the ``mdsr`` command and its worker
processes set to one unless the environment says otherwise (a script sets the variable itself).

Example
-------
>>> with one_blas_thread():
...     pass  # factorise, solve
"""

from __future__ import annotations

import contextlib
import sys

__all__ = ["one_blas_thread"]

#: (number of modules imported, threadpoolctl controller) of the last look at the loaded libraries
_FOUND: tuple | None = None


def _controller():
    """threadpoolctl's view of the loaded BLAS libraries: looked up again whenever modules were imported
    since the last look (an import is what loads a library; a look costs about a millisecond)."""
    global _FOUND
    from threadpoolctl import ThreadpoolController

    if _FOUND is None or _FOUND[0] != len(sys.modules):
        _FOUND = (len(sys.modules), ThreadpoolController())
    return _FOUND[1]


@contextlib.contextmanager
def one_blas_thread():
    """Run the block with one thread in every BLAS library threadpoolctl finds; restored afterwards."""
    with _controller().limit(limits=1, user_api="blas"):
        yield
