"""Writes its model's C3 once a sibling has started too, or after a pause if none does (run one after
the other, the first waits out the pause; run at once, the two see each other and end together)."""

import os
import time

REPORT = "slow.pdf"
ORDER = 1
PAUSE = 1.5  # [s] the longest wait for a sibling


def build(out, model):
    started = time.time()
    out.parent.mkdir(parents=True, exist_ok=True)
    out.with_suffix(".started").write_text(str(os.getpid()))
    while time.time() - started < PAUSE:
        if any(p != out.with_suffix(".started") for p in out.parent.glob("*.started")):
            break
        time.sleep(0.01)
    time.sleep(0.05)  # the sibling, which found this one started, may still be checking
    out.write_text(
        f"C3 = {model.constants.C3!r}\npid = {os.getpid()}\nstarted = {started!r}\nended = {time.time()!r}\n"
        f"blas = {os.environ.get('OPENBLAS_NUM_THREADS')}\n"
    )
