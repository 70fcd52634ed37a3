"""Analysis scripts that turn the library into PDF reports (shipped as maglev_oc.analyses).

Each script has ``REPORT`` (its PDF's file name), ``ORDER`` (its place in ``maglev-oc report``),
``build(out, model)`` and a ``main()`` that parses :func:`analysis_parser`'s command line.
``build`` computes, then lays out named pages, and returns what the PDF says
(:class:`maglev_oc.reporting.pdf.ReportContents`); where the computation is long, the layout is
a separate ``write_report(out, study)`` that tests call on a study they already have.
"""

from __future__ import annotations

import argparse
from pathlib import Path

__all__ = ["analysis_parser"]


def analysis_parser(doc: str, report: str) -> argparse.ArgumentParser:
    """The command line every analysis script shares: ``--out`` and ``--params``."""
    parser = argparse.ArgumentParser(description=doc.splitlines()[0])
    parser.add_argument("--out", type=Path, default=Path("reports") / report, help="PDF to write")
    parser.add_argument("--params", type=Path, help="stage/constants JSON (default: papers)")
    return parser
