"""One BLAS thread during solves (mdsr_opt.mechanics.blas): set inside, restored outside."""

from mdsr_opt.mechanics.blas import _libraries, one_blas_thread


def test_one_thread_inside_and_the_previous_counts_restored():
    libs = _libraries()
    assert len(libs) >= 1  # casadi, numpy and scipy each ship an OpenBLAS with these functions
    before = [int(get()) for get, _ in libs]
    with one_blas_thread():
        assert [int(get()) for get, _ in libs] == [1] * len(libs)
        with one_blas_thread():  # nesting is harmless
            assert [int(get()) for get, _ in libs] == [1] * len(libs)
    assert [int(get()) for get, _ in libs] == before
    try:
        with one_blas_thread():
            raise RuntimeError("solver failed")
    except RuntimeError:
        pass
    assert [int(get()) for get, _ in libs] == before
