"""Writes its model's C3 after a pause (long enough that two of them overlap when run at once)."""

import os
import time

REPORT = "slow.pdf"
ORDER = 1


def build(out, model):
    started = time.time()
    time.sleep(1.5)
    out.parent.mkdir(parents=True, exist_ok=True)
    out.write_text(
        f"C3 = {model.constants.C3!r}\npid = {os.getpid()}\nstarted = {started!r}\nended = {time.time()!r}\n"
        f"blas = {os.environ.get('OPENBLAS_NUM_THREADS')}\n"
    )
