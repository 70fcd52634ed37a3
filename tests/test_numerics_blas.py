"""``one_blas_thread``: the BLAS thread count inside and after, and a count the user set kept."""

from __future__ import annotations

import pytest
from threadpoolctl import threadpool_info, threadpool_limits

from maglev_oc.numerics import BLAS_THREAD_VARIABLES, one_blas_thread


def _blas_threads() -> list[int]:
    return [p["num_threads"] for p in threadpool_info() if p["user_api"] == "blas"]


@pytest.fixture
def two_threads(monkeypatch):
    """BLAS asked for 2 threads, no count in the environment (tests/conftest.py sets one); the
    counts the loaded BLAS libraries then have (a library started with one may stay at one)."""
    for k in BLAS_THREAD_VARIABLES:
        monkeypatch.delenv(k, raising=False)
    with threadpool_limits(limits=2, user_api="blas"):
        counts = _blas_threads()
        if 2 not in counts:
            pytest.skip("no BLAS library here that threadpoolctl can set to 2 threads")
        yield counts


def test_the_function_runs_on_one_thread_and_the_count_comes_back(two_threads):
    assert set(one_blas_thread(_blas_threads)()) == {1}
    assert _blas_threads() == two_threads  # restored on return


def test_the_count_comes_back_when_the_function_raises(two_threads):
    def fails():
        raise ValueError("on purpose")

    with pytest.raises(ValueError, match="on purpose"):
        one_blas_thread(fails)()
    assert _blas_threads() == two_threads


def test_a_count_the_user_set_is_kept(two_threads, monkeypatch):
    monkeypatch.setenv("OPENBLAS_NUM_THREADS", "2")
    assert one_blas_thread(_blas_threads)() == two_threads


def test_diagnose_is_wrapped():
    from maglev_oc.diagnosis.pipeline import diagnose

    assert diagnose.__wrapped__.__name__ == "diagnose"  # functools.wraps keeps the name and doc
    assert "Diagnose ``logs``" in diagnose.__doc__
