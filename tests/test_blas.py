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
