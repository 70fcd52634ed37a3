"""``without_hugepage_advice``: NumPy's huge-page advice off inside and restored after, a setting
the user chose kept, and the diagnosis run under it (numerics.py gives the measurement)."""

from __future__ import annotations

import pytest

from maglev_oc.numerics import HUGEPAGE_VARIABLE, _hugepage_switch, without_hugepage_advice

SWITCH = _hugepage_switch()
pytestmark = pytest.mark.skipif(SWITCH is None, reason="this NumPy has no switch of its huge-page advice")


def _advice() -> bool:
    """NumPy's current setting (set and put back: the setter is the only reader)."""
    now = SWITCH(True)
    SWITCH(now)
    return now


@pytest.fixture
def advice_on(monkeypatch):
    monkeypatch.delenv(HUGEPAGE_VARIABLE, raising=False)
    before = SWITCH(True)
    yield
    SWITCH(before)


def test_the_advice_is_off_inside_and_back_on_after(advice_on):
    assert without_hugepage_advice(_advice)() is False
    assert _advice() is True


def test_the_advice_comes_back_when_the_function_raises(advice_on):
    def fails():
        raise ValueError("on purpose")

    with pytest.raises(ValueError, match="on purpose"):
        without_hugepage_advice(fails)()
    assert _advice() is True


def test_a_setting_the_user_chose_is_kept(advice_on, monkeypatch):
    monkeypatch.setenv(HUGEPAGE_VARIABLE, "1")
    assert without_hugepage_advice(_advice)() is True


def test_the_diagnosis_runs_without_the_advice(advice_on, monkeypatch):
    from maglev_oc.diagnosis import pipeline

    seen = []

    def spy(*args, **kwargs):
        seen.append(_advice())
        raise RuntimeError("stop here")

    monkeypatch.setattr(pipeline, "_prepare", spy)
    with pytest.raises(RuntimeError, match="stop here"):
        pipeline.diagnose([])
    assert seen == [False] and _advice() is True
