"""Like :mod:`tests.fake_analyses.slow`, under another name."""

from tests.fake_analyses.slow import build

REPORT = "slower.pdf"
ORDER = 2
__all__ = ["ORDER", "REPORT", "build"]
