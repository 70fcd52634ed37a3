"""Reading the C harness's report (``maglev_oc.control.codegen.run_harness``) without compiling
anything: a stand-in executable prints the lines ``bench/nmpc_c/harness.c`` prints (keys read
from its printf formats, so the two stay one contract) and the timings come back in seconds, the
verdict from the failed calls, the arguments as the harness takes them; a harness that exits
with an error raises with its message. The compiled harness runs only in the slow NMPC tests.
A Python subprocess each, well under a second."""

from __future__ import annotations

import re
import stat
import sys
from pathlib import Path

import pytest

from maglev_oc.control.codegen import REPO_HARNESS, run_harness
from maglev_oc.errors import SolverError


def _stand_in(tmp_path: Path, lines: list[str], code: int = 0) -> Path:
    exe = tmp_path / "harness"
    body = "".join(f"print({line!r})\n" for line in lines)
    exe.write_text(
        f"#!{sys.executable}\nimport sys\n"
        f"open({str(tmp_path / 'args.txt')!r}, 'w').write(' '.join(sys.argv[1:]))\n"
        f"{body}sys.stderr.write('bad instances file')\nsys.exit({code})\n"
    )
    exe.chmod(exe.stat().st_mode | stat.S_IEXEC)
    return exe


def _report(values: dict[str, str]) -> list[str]:
    keys = re.findall(r'printf\("(\w+): %', REPO_HARNESS.read_text())
    assert keys == ["instances", "calls_timed", "failed_calls", "median_us", "p99_us", "worst_us"]
    return [f"{k}: {values[k]}" for k in keys]


@pytest.mark.parametrize("failed", [0, 2])
def test_the_report_is_read_in_seconds_with_its_verdict(tmp_path, failed):
    values = {
        "instances": "40",
        "calls_timed": "120",
        "failed_calls": str(failed),
        "median_us": "12.500",
        "p99_us": "30.250",
        "worst_us": "101.000",
    }
    exe = _stand_in(tmp_path, _report(values))
    t = run_harness(exe, tmp_path / "inst.bin", tmp_path / "out.bin", repeat=3)
    assert (tmp_path / "args.txt").read_text() == f"{tmp_path / 'inst.bin'} {tmp_path / 'out.bin'} 3"
    assert (t.instances, t.calls, t.failed_calls) == (40, 120, failed)
    assert t.success == (failed == 0) and t.status == ("replayed" if failed == 0 else "failed_calls")
    # microseconds to seconds: exact decimal inputs, rounding only (1e-15)
    assert t.median == pytest.approx(12.5e-6, rel=1e-15)
    assert t.p99 == pytest.approx(30.25e-6, rel=1e-15)
    assert t.worst == pytest.approx(101e-6, rel=1e-15)
    assert t.timings["harness"] > 0


def test_a_harness_that_fails_raises_with_its_message(tmp_path):
    exe = _stand_in(tmp_path, [], code=3)
    with pytest.raises(SolverError, match="bad instances file"):
        run_harness(exe, tmp_path / "inst.bin")
