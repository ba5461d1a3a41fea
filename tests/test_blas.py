"""One BLAS thread during solves (mdsr_opt.mechanics.blas): set inside, restored outside (but CasADi's)."""

from mdsr_opt.mechanics.blas import _libraries, one_blas_thread


def test_one_thread_inside_and_the_previous_counts_restored_but_casadis():
    libs = _libraries()
    assert len(libs) == 3 and [keep for *_, keep in libs] == [True, False, False]  # casadi, numpy, scipy
    original = [int(get()) for get, *_ in libs]
    try:
        _check_counts(libs)
    finally:  # the session's counts as they were (the test sets them to 2 to see the restore)
        for (_get, put, _keep), n in zip(libs, original):
            put(n)


def _check_counts(libs):
    for _get, put, _keep in libs:
        put(2)
    before = [int(get()) for get, *_ in libs]
    assert before == [2, 2, 2]
    after = [1, 2, 2]  # CasADi's copy stays at one thread: setting it back woke its threads to spin
    with one_blas_thread():
        assert [int(get()) for get, *_ in libs] == [1] * len(libs)
        with one_blas_thread():  # nesting is harmless
            assert [int(get()) for get, *_ in libs] == [1] * len(libs)
    assert [int(get()) for get, *_ in libs] == after
    libs[0][1](2)
    try:
        with one_blas_thread():
            raise RuntimeError("solver failed")
    except RuntimeError:
        pass
    assert [int(get()) for get, *_ in libs] == after


_ONE_COPY = r"""
import ctypes, sys
import casadi
from mdsr_opt.mechanics.blas import one_blas_thread

def solve():  # IPOPT's plugin loads CasADi's OpenBLAS (by its soname) for MUMPS
    x = casadi.SX.sym("x")
    s = casadi.nlpsol("s", "ipopt", {"x": x, "f": (x - 1) ** 2},
                      {"print_time": False, "ipopt.print_level": 0, "ipopt.sb": "yes"})
    s(x0=0)

if sys.argv[1] == "ipopt-first":
    solve()
with one_blas_thread():
    pass
solve()
copies = sorted({line.split(None, 5)[5].strip() for line in open("/proc/self/maps")
                 if "libcasadi-tp-openblas" in line})
print(len(copies), ctypes.CDLL(copies[0]).openblas_get_num_threads())
"""


def test_casadis_copy_is_the_one_mumps_uses_whichever_loads_first():
    # the wheel ships CasADi's OpenBLAS as three separate files; opening another one than MUMPS's by its
    # path had made a second copy, set to one thread while MUMPS's ran with two (one spinning beside solves)
    import subprocess
    import sys

    for order in ("ipopt-first", "ours-first"):
        out = subprocess.run([sys.executable, "-c", _ONE_COPY, order], capture_output=True, text=True, timeout=120)
        assert out.returncode == 0, out.stderr[-2000:]
        assert out.stdout.split()[-2:] == ["1", "1"], (order, out.stdout)  # one copy mapped, at one thread
