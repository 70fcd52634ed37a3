"""Run the analysis scripts that write the reports, several at a time.

Each analysis runs in a process of its own (spawned, not forked: CasADi and BLAS threads do not
survive a fork), the longest first, so that ``maglev-oc report`` takes about as long as its
longest analysis on a machine with as many cores as there are long analyses. One failing analysis
does not stop the others; its error is returned, not raised.
"""

from __future__ import annotations

import contextlib
import importlib
import inspect
import multiprocessing
import os
import pkgutil
import time
import traceback
from collections.abc import Callable, Sequence
from concurrent.futures import FIRST_COMPLETED, ProcessPoolExecutor, wait
from dataclasses import dataclass
from pathlib import Path

__all__ = ["ANALYSES", "ReportRun", "analysis_modules", "run_reports"]

LONGEST_FIRST = ("controllers", "operating_region", "microstepper", "identification", "closing_the_loop")
"""Analyses in the order they start when run in parallel (measured: the longest first)."""


@dataclass(frozen=True)
class ReportRun:
    """How one analysis went: its PDF, wall time [s], and the error (None when it succeeded)."""

    name: str
    path: Path
    seconds: float
    error: str | None = None

    @property
    def success(self) -> bool:
        return self.error is None


ANALYSES = "maglev_oc.analyses"


def analysis_modules(package: str = ANALYSES) -> dict[str, object]:
    """Analysis scripts by name (``package``.<name>), each with REPORT and build(), in the order
    of their ORDER."""
    pkg = importlib.import_module(package)
    found = {}
    for info in pkgutil.iter_modules(pkg.__path__):
        module = importlib.import_module(f"{pkg.__name__}.{info.name}")
        if hasattr(module, "build") and hasattr(module, "REPORT"):
            found[info.name] = module
    return dict(sorted(found.items(), key=lambda kv: getattr(kv[1], "ORDER", 100)))


def _build(name: str, out: str, params: str | None, package: str) -> ReportRun:
    """Run one analysis (in a worker process, or in this one)."""
    from maglev_oc.model.loading import load_model

    t0 = time.perf_counter()
    path = Path(out)
    try:
        module = analysis_modules(package)[name]
        stage = Path(params) if params else None
        # an analysis that reads more of the stage file than the model (the operating region: the
        # constants' covariance) takes the file too
        takes_file = "params" in inspect.signature(module.build).parameters
        module.build(path, load_model(stage), **({"params": stage} if takes_file else {}))
    except Exception as err:  # one failing report must not stop the others
        detail = "".join(traceback.format_exception_only(err)).strip()
        return ReportRun(name, path, time.perf_counter() - t0, detail)
    return ReportRun(name, path, time.perf_counter() - t0)


@contextlib.contextmanager
def _blas_threads(n: int):
    """Spawned workers start with ``n`` BLAS threads each (cores / workers), unless the user set
    the count: with one BLAS thread per core already busy, OpenBLAS's threads spin against each
    other and the other workers (measured: a diagnosis 2.2x slower with 2 threads than with 1 on
    two loaded cores; a 200-column block Gram 13x). Workers are spawned, so they read the
    environment as it is here when the pool starts them."""
    from maglev_oc.numerics import BLAS_THREAD_VARIABLES  # here: the runner itself stays light

    saved = {k: os.environ.get(k) for k in BLAS_THREAD_VARIABLES}
    if all(v is None for v in saved.values()):
        os.environ.update({k: str(n) for k in BLAS_THREAD_VARIABLES})
    try:
        yield
    finally:
        for k, v in saved.items():
            if v is None:
                os.environ.pop(k, None)
            else:
                os.environ[k] = v


def run_reports(
    names: Sequence[str],
    out_dir: Path,
    *,
    params: Path | None = None,
    jobs: int | None = None,
    done: Callable[[ReportRun], None] = lambda run: None,
    package: str = ANALYSES,
) -> list[ReportRun]:
    """Run the analyses ``names`` (modules of ``package``) into ``out_dir`` with up to ``jobs``
    processes (default: the cores this process may use); ``done`` is called as each finishes.
    Returns the runs in the order of ``names``."""
    modules = analysis_modules(package)
    unknown = [n for n in names if n not in modules]
    if unknown:
        raise KeyError(f"unknown analysis {unknown}; available: {', '.join(modules)}")
    targets = {n: str(out_dir / modules[n].REPORT) for n in names}
    param_text = str(params) if params is not None else None
    jobs = jobs or len(os.sched_getaffinity(0))
    runs: dict[str, ReportRun] = {}
    if jobs <= 1 or len(names) == 1:
        for n in names:
            runs[n] = _build(n, targets[n], param_text, package)
            done(runs[n])
        return [runs[n] for n in names]
    order = sorted(names, key=lambda n: LONGEST_FIRST.index(n) if n in LONGEST_FIRST else len(LONGEST_FIRST))
    context = multiprocessing.get_context("spawn")
    workers = min(jobs, len(names))
    with (
        _blas_threads(max(1, len(os.sched_getaffinity(0)) // workers)),
        ProcessPoolExecutor(workers, mp_context=context) as pool,
    ):
        pending = {pool.submit(_build, n, targets[n], param_text, package): n for n in order}
        try:
            while pending:
                finished, _ = wait(pending, return_when=FIRST_COMPLETED)
                for future in finished:
                    name = pending.pop(future)
                    try:
                        runs[name] = future.result()
                    except Exception as err:  # the worker itself died (e.g. out of memory)
                        runs[name] = ReportRun(name, Path(targets[name]), float("nan"), f"worker died: {err}")
                    done(runs[name])
        except KeyboardInterrupt:
            pool.shutdown(wait=False, cancel_futures=True)
            raise
    return [runs[n] for n in names]
