"""One BLAS thread during solves (mdsr_opt.mechanics.blas, through threadpoolctl): set inside, restored outside."""

import pytest

import numpy  # noqa: F401 - its OpenBLAS loaded
import scipy.sparse.linalg  # noqa: F401 - and scipy's
from threadpoolctl import threadpool_info, threadpool_limits

from mdsr_opt.mechanics.blas import one_blas_thread


def _counts() -> list[int]:
    return [lib["num_threads"] for lib in threadpool_info() if lib["user_api"] == "blas"]


def test_one_thread_inside_and_the_previous_counts_restored():
    with threadpool_limits(2, user_api="blas"):  # the session's counts as they were afterwards
        assert len(_counts()) >= 2 and set(_counts()) == {2}  # numpy's and scipy's copies
        with one_blas_thread():
            assert set(_counts()) == {1}
            with one_blas_thread():  # nesting is harmless
                assert set(_counts()) == {1}
            assert set(_counts()) == {1}
        assert set(_counts()) == {2}
        with pytest.raises(RuntimeError, match="solver failed"):
            with one_blas_thread():
                raise RuntimeError("solver failed")
        assert set(_counts()) == {2}


def test_a_library_loaded_after_the_first_use_is_limited_too(monkeypatch):
    """The libraries are looked up again once modules were imported since the last look."""
    import sys

    from mdsr_opt.mechanics import blas

    with one_blas_thread():
        pass
    seen = blas._FOUND[1]
    with one_blas_thread():  # nothing imported meanwhile: the same look
        pass
    assert blas._FOUND[1] is seen
    monkeypatch.setitem(sys.modules, "a_module_imported_since", sys)
    with one_blas_thread():
        assert set(_counts()) == {1}
    assert blas._FOUND[1] is not seen
