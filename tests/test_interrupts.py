"""Ctrl-C that an extension swallowed is still honoured (``maglev_oc.interrupts``): CasADi's
Function constructor cleared the KeyboardInterrupt of a diagnosis interrupted while it built a
model, which then ran on and wrote its output with status 0. Here the swallowing is done by hand
(``except KeyboardInterrupt: pass``) around a real SIGINT, deterministically."""

from __future__ import annotations

import os
import signal

import pytest

from maglev_oc import cli, interrupts
from maglev_oc.fileio import write_text_atomic


@pytest.fixture(autouse=True)
def pythons_own_handler():
    """Python's own SIGINT handler, as a program started from a shell has it: a test worker's may be
    another (the test run's, or one a previous test left), under which ``honoured`` does nothing."""
    previous = signal.signal(signal.SIGINT, signal.default_int_handler)
    yield
    signal.signal(signal.SIGINT, previous)


def _swallowed_interrupt() -> None:
    """A real SIGINT to this process, whose KeyboardInterrupt is then lost as CasADi lost it."""
    try:
        os.kill(os.getpid(), signal.SIGINT)
        for _ in range(1000):  # the handler runs at the next bytecode
            pass
    except KeyboardInterrupt:
        pass


def test_a_swallowed_interrupt_is_raised_again_and_nothing_is_written(tmp_path):
    out = tmp_path / "out.json"
    with interrupts.honoured():
        interrupts.raise_if_interrupted()  # nothing pending: no effect
        _swallowed_interrupt()
        with pytest.raises(KeyboardInterrupt):
            interrupts.raise_if_interrupted()
        with pytest.raises(KeyboardInterrupt):
            write_text_atomic(out, "{}")
    assert list(tmp_path.iterdir()) == []  # neither the output nor its temporary file
    # after the block: Python's own handler again, nothing pending, outputs written
    assert signal.getsignal(signal.SIGINT) is signal.default_int_handler
    interrupts.raise_if_interrupted()
    write_text_atomic(out, "{}")
    assert out.read_text() == "{}"


def test_a_command_whose_interrupt_was_swallowed_ends_with_130_and_writes_nothing(
    tmp_path, monkeypatch, capsys
):
    out = tmp_path / "d.json"

    def swallowing(args):
        _swallowed_interrupt()
        write_text_atomic(args.json, "{}")
        return 0

    monkeypatch.setattr(cli, "cmd_diagnose", swallowing)
    code = cli.main(["diagnose", str(tmp_path / "any.csv"), "--json", str(out)])
    assert code == cli.EXIT_INTERRUPTED
    assert "interrupted" in capsys.readouterr().err
    assert not out.exists() and list(tmp_path.iterdir()) == []


def test_where_sigint_is_ignored_it_stays_ignored():
    # a program started in the background by nohup ignores SIGINT: honoured() leaves that alone
    previous = signal.signal(signal.SIGINT, signal.SIG_IGN)
    try:
        with interrupts.honoured():
            assert signal.getsignal(signal.SIGINT) is signal.SIG_IGN
    finally:
        signal.signal(signal.SIGINT, previous)


def test_an_error_raised_after_a_swallowed_interrupt_leaves_as_the_interrupt():
    with pytest.raises(KeyboardInterrupt) as caught, interrupts.honoured():
        _swallowed_interrupt()
        raise RuntimeError("Error in Function::call for 'f'")  # what the extension raised instead
    assert isinstance(caught.value.__cause__, RuntimeError)
    with pytest.raises(RuntimeError), interrupts.honoured():  # without an interrupt: itself
        raise RuntimeError("a bug")
