"""Compiled closed loops kept between runs (maglev_oc.sim.library_cache): a library of the same
source and flags is loaded from the cache, never compiled again, and runs the same; anything else
(other code, other flags, no cache) is compiled; a cache that cannot be used is no error."""

from __future__ import annotations

import casadi as ca
import numpy as np
import pytest

from maglev_oc.numerics import c_compiler
from maglev_oc.sim import library_cache
from maglev_oc.sim.native import NativeBatch, NativeLoop

pytestmark = pytest.mark.skipif(c_compiler() is None, reason="no C compiler")


def _step(gain: float) -> ca.Function:
    """z_next = gain z + r, out = z + w: a loop whose runs are known in closed form."""
    z, r, w = ca.SX.sym("z", 2), ca.SX.sym("r", 2), ca.SX.sym("w", 1)
    return ca.Function("step", [z, r, w], [gain * z + r, z + w])


def _run(loop: NativeLoop, n: int = 5):
    r = np.ones((2, n))
    w = np.arange(n, dtype=float)[None, :]
    return loop(np.array([1.0, -1.0]), r, w)


def _expected(gain: float, n: int = 5):
    """The closed form of :func:`_run`: z_k+1 = gain z_k + 1 from z_0 = (1, -1), out_k = z_k + k."""
    z, out = np.array([1.0, -1.0]), []
    for k in range(n):
        out.append(z + k)
        z = gain * z + 1.0
    return np.array(out).T, z


def _libraries(cache) -> list:
    return sorted((cache / "native").glob("*.so"))


def test_the_same_loop_is_loaded_from_the_cache_and_runs_the_same(tmp_path):
    first = NativeLoop(_step(0.5), cache=tmp_path)
    assert not first.cached and len(_libraries(tmp_path)) == 1
    again = NativeLoop(_step(0.5), cache=tmp_path)
    assert again.cached and len(_libraries(tmp_path)) == 1
    out, zf = _run(again)
    want_out, want_z = _expected(0.5)
    np.testing.assert_allclose(out, want_out, rtol=0, atol=1e-15)
    np.testing.assert_allclose(zf, want_z, rtol=0, atol=1e-15)
    np.testing.assert_array_equal(_run(first)[0], out)


def test_other_code_other_flags_or_no_cache_are_compiled(tmp_path):
    NativeLoop(_step(0.5), cache=tmp_path)
    other = NativeLoop(_step(0.25), cache=tmp_path)
    assert not other.cached and len(_libraries(tmp_path)) == 2
    # a gain of 0.25 runs as one (not the cached 0.5 loop)
    np.testing.assert_allclose(_run(other)[1], _expected(0.25)[1], rtol=0, atol=1e-15)
    flags = NativeLoop(_step(0.5), flags=("-O1",), cache=tmp_path)
    assert not flags.cached and len(_libraries(tmp_path)) == 3
    assert not NativeLoop(_step(0.5), cache=False).cached
    assert len(_libraries(tmp_path)) == 3


def test_the_batch_loop_is_cached_too(tmp_path):
    z, r, w = ca.SX.sym("z", 1), ca.SX.sym("r", 1), ca.SX.sym("w", 1)
    step = ca.Function("step", [z, r, w], [z + r])
    assert not NativeBatch(step, cache=tmp_path).cached
    batch = NativeBatch(step, cache=tmp_path)
    assert batch.cached
    np.testing.assert_array_equal(
        batch(np.array([[0.0, 2.0]]), np.ones((1, 3)), np.zeros((1, 3))), [[3.0, 5.0]]
    )


def test_the_default_cache_is_the_users(tmp_path, monkeypatch):
    monkeypatch.setenv("MAGLEV_OC_CACHE", str(tmp_path / "mine"))
    assert library_cache.user_cache() == tmp_path / "mine"
    NativeLoop(_step(0.5))
    assert len(_libraries(tmp_path / "mine")) == 1
    monkeypatch.delenv("MAGLEV_OC_CACHE")
    monkeypatch.setenv("XDG_CACHE_HOME", str(tmp_path / "xdg"))
    assert library_cache.user_cache() == tmp_path / "xdg" / "maglev_oc"


def test_a_cache_that_cannot_be_written_is_no_error(tmp_path):
    blocked = tmp_path / "a_file"  # the cache's directory cannot be made (root writes any directory)
    blocked.write_text("")
    loop = NativeLoop(_step(0.5), cache=blocked)
    assert not loop.cached and blocked.read_text() == ""
    np.testing.assert_allclose(_run(loop)[1], _expected(0.5)[1], rtol=0, atol=1e-15)


def test_a_cache_entry_that_does_not_load_is_compiled_again_and_replaced(tmp_path):
    NativeLoop(_step(0.5), cache=tmp_path)
    (kept,) = _libraries(tmp_path)
    kept.write_bytes(b"not a shared library")
    loop = NativeLoop(_step(0.5), cache=tmp_path)
    assert not loop.cached
    assert kept.read_bytes()[:4] == b"\x7fELF"  # replaced by the library compiled again
    assert NativeLoop(_step(0.5), cache=tmp_path).cached


def test_keep_writes_whole_or_nothing(tmp_path):
    built = tmp_path / "lib.so"
    built.write_bytes(b"library")
    kept = tmp_path / "cache" / "x.so"
    assert library_cache.keep(built, kept) and kept.read_bytes() == b"library"
    assert list(kept.parent.iterdir()) == [kept]  # no partial file left beside it
    (tmp_path / "file").write_text("")
    assert not library_cache.keep(built, tmp_path / "file" / "x.so")  # its directory is a file
    # the key covers the source and the flags
    assert library_cache.cache_key("a", ("-O1",)) != library_cache.cache_key("a", ("-O2",))
    assert library_cache.cache_key("a", ()) != library_cache.cache_key("b", ())
