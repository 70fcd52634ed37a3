"""Ctrl-C that no extension module can lose.

Python turns SIGINT into a KeyboardInterrupt raised at the next bytecode it runs. An extension
module whose C code runs Python and then clears the error it raised loses the interrupt. CasADi's
``Function`` constructor did so (where in its wrapper was not traced): a diagnosis of a 150 s log
interrupted 10.25 s in, while the refit built a model's Functions, ran to its end, wrote its output
and exited with status 0 (``py-spy dump`` at the signal; 1 of 7 interrupts sent 10.0 to 10.6 s in,
the others ended with status 130 at once).

Under :func:`honoured` the signal is also remembered, and :func:`raise_if_interrupted` raises it
again between the steps of a long computation and before an output is put in place
(:mod:`maglev_oc.fileio`), so that an interrupted program writes nothing whatever swallowed the
exception.
"""

from __future__ import annotations

import contextlib
import signal
import threading
from collections.abc import Iterator

__all__ = ["honoured", "raise_if_interrupted"]

_pending = False


def _interrupted(signum, frame) -> None:
    global _pending
    _pending = True
    raise KeyboardInterrupt


@contextlib.contextmanager
def honoured() -> Iterator[None]:
    """Remember Ctrl-C within the block (see the module doc); an error that leaves it after a
    Ctrl-C leaves it as the KeyboardInterrupt (from that error). Only where Python's own handler is
    installed (the main thread of a process that does not ignore SIGINT, as a program run in the
    background with ``nohup`` does); elsewhere the block runs as it would without it."""
    global _pending
    _pending = False
    if threading.current_thread() is not threading.main_thread() or (
        signal.getsignal(signal.SIGINT) is not signal.default_int_handler
    ):
        yield
        return
    previous = signal.signal(signal.SIGINT, _interrupted)
    try:
        yield
    except Exception as err:  # an extension's own error for the interrupt it swallowed
        if _pending:
            raise KeyboardInterrupt from err
        raise
    finally:
        signal.signal(signal.SIGINT, previous)
        _pending = False


def raise_if_interrupted() -> None:
    """Raise KeyboardInterrupt if Ctrl-C came within :func:`honoured` and was swallowed since."""
    if _pending:
        raise KeyboardInterrupt
