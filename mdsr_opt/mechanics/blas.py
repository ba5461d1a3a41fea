"""One BLAS thread during a solve: sparse factorisations are not worth two threads fighting over cores.

CasADi's MUMPS (inside IPOPT) and scipy's SuperLU call OpenBLAS, each its own bundled copy (CasADi,
numpy and scipy ship one each). With two threads on a machine whose cores are busy with other work, the
threads wait for each other: IPOPT's solve at 30k nodes measured 2.5 s with the default threads and 0.9 s
with one, on this 2-core machine while other processes ran. :func:`one_blas_thread` sets every loaded
copy to one thread for the duration of a ``with`` block and restores the previous counts afterwards, but
CasADi's, which it leaves at one thread: setting that copy's count back and forth woke its idle threads,
which then spun on the core beside the solve (five toggles, then 0.3 s asleep: 0.185 s of CPU; numpy's and
scipy's copies: none). Only CasADi's own solvers use that copy (IPOPT's MUMPS here). Where a library or its
thread functions are missing it does nothing.

Example
-------
>>> with one_blas_thread():
...     pass  # factorise, solve
"""

from __future__ import annotations

import contextlib
import ctypes
import glob
import os
import re

__all__ = ["one_blas_thread"]

#: (get, set) function names of the OpenBLAS builds shipped with casadi, numpy (64-bit) and scipy
_NAMES = (("openblas_get_num_threads", "openblas_set_num_threads"),
          ("scipy_openblas_get_num_threads64_", "scipy_openblas_set_num_threads64_"),
          ("scipy_openblas_get_num_threads", "scipy_openblas_set_num_threads"))
_LIBS: list | None = None


def _casadi_copies(folder: str) -> list[str]:
    """CasADi's OpenBLAS as IPOPT's MUMPS uses it: the copies this process has mapped, else the file named
    like its soname (``libcasadi-tp-openblas.so.0``).

    The wheel ships the library three times, as separate files (``.so``, ``.so.0``, ``.so.0.3``). Opened by
    the path of another file than the one MUMPS loaded by its soname, it is a second copy: its thread count
    was set to one while MUMPS ran with two, whose idle thread spun beside every solve (0.13 CPU-s in a 3k
    node design of 0.6 s) whenever the IPOPT plugin had loaded first."""
    paths = sorted(glob.glob(os.path.join(folder, "libcasadi-tp-openblas.so*")))
    mapped = _mapped(paths)
    if mapped:
        return mapped
    soname = [p for p in paths if re.search(r"\.so\.\d+$", p)]
    return (soname or paths)[:1]


def _mapped(paths: list[str]) -> list[str]:
    """Those of ``paths`` mapped into this process (Linux's ``/proc/self/maps``; elsewhere none)."""
    names = {os.path.basename(p) for p in paths}
    try:
        with open("/proc/self/maps") as f:  # only the lines of these files' names are resolved
            fields = [line.split(None, 5) for line in f if any(n in line for n in names)]
    except OSError:
        return []
    real = {os.path.realpath(f[5].strip()) for f in fields if len(f) == 6}
    return [p for p in paths if os.path.realpath(p) in real]


def _candidates() -> list[str]:
    import casadi
    import numpy
    import scipy

    out = _casadi_copies(os.path.dirname(casadi.__file__))
    for pkg in (numpy, scipy):
        libs = os.path.join(os.path.dirname(os.path.dirname(pkg.__file__)), f"{pkg.__name__}.libs")
        out += sorted(glob.glob(os.path.join(libs, "*openblas*.so*")))
    return out


def _libraries() -> list:
    """``(get, set, keep)`` of every copy found: its thread-count functions, and whether
    :func:`one_blas_thread` leaves it at one thread (CasADi's)."""
    global _LIBS
    if _LIBS is None:
        found = []
        for path in _candidates():
            try:
                lib = ctypes.CDLL(path)  # a library already loaded is the same handle
            except OSError:
                continue
            for get, put in _NAMES:
                if hasattr(lib, get) and hasattr(lib, put):
                    found.append((getattr(lib, get), getattr(lib, put), "casadi" in os.path.basename(path)))
                    break
        _LIBS = found
    return _LIBS


@contextlib.contextmanager
def one_blas_thread():
    """Run the block with one OpenBLAS thread in every bundled copy: restored afterwards, but CasADi's,
    which stays at one (see the module's notes)."""
    saved = []
    for get, put, keep in _libraries():
        try:
            n = int(get())
            if n != 1:
                put(1)
                if not keep:
                    saved.append((put, n))
        except Exception:  # noqa: BLE001 - a foreign build without these functions: leave it
            continue
    try:
        yield
    finally:
        for put, n in saved:
            put(n)
