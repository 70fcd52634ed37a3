"""Mutation testing with mutmut (the ``mutation`` extra), one module or package at a time.

    python bench/mutation.py --mutate maglev_oc/region/interval.py \
        --tests tests/test_region_interval.py tests/test_region_soundness.py [--children 2]

Copies ``maglev_oc/``, ``tests/`` and ``pyproject.toml`` into a scratch folder (mutmut 3 writes
its mutants beside the sources), adds a ``[tool.mutmut]`` table that mutates only ``--mutate``
and runs only ``--tests``, runs ``mutmut run``, and prints the counts and the score:
killed (and timed out) over all mutants, "no tests" counted as survivors. Survivors are listed
with ``--show`` (their diffs, from ``mutmut show``). Not run in CI: a module takes minutes to
hours, since each mutant reruns the tests that reach it.
"""

from __future__ import annotations

import argparse
import collections
import shutil
import subprocess
import sys
import tempfile
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--mutate", required=True, help="a module or package path under maglev_oc/")
    parser.add_argument("--tests", nargs="+", required=True, help="test files that guard it")
    parser.add_argument("--children", type=int, default=2)
    parser.add_argument("--show", action="store_true", help="print the surviving mutants' diffs")
    args = parser.parse_args()
    if shutil.which("mutmut") is None:
        raise SystemExit('mutmut is missing: pip install -e ".[mutation]"')
    with tempfile.TemporaryDirectory() as tmp:
        work = Path(tmp)
        for name in ("maglev_oc", "tests"):
            shutil.copytree(ROOT / name, work / name, ignore=shutil.ignore_patterns("__pycache__"))
        tests = ", ".join(f'"{t}"' for t in args.tests)
        config = (
            "\n[tool.mutmut]\n"
            f'source_paths = ["{args.mutate}"]\n'
            f"pytest_add_cli_args_test_selection = [{tests}]\n"
            'also_copy = ["tests/", "maglev_oc/"]\n'
        )
        (work / "pyproject.toml").write_text((ROOT / "pyproject.toml").read_text() + config)
        subprocess.run(["mutmut", "run", "--max-children", str(args.children)], cwd=work, capture_output=True)
        out = subprocess.run(
            ["mutmut", "results", "--all", "true"], cwd=work, capture_output=True, text=True
        ).stdout
        status = {}
        for line in out.splitlines():
            name, _, word = line.strip().rpartition(": ")
            if name:
                status[name] = word
        counts = collections.Counter(status.values())
        detected = counts["killed"] + counts["timeout"]
        total = sum(counts.values())
        print(f"{args.mutate}: {total} mutants; " + ", ".join(f"{k} {v}" for k, v in sorted(counts.items())))
        print(f"score (killed or timed out / all): {detected / max(total, 1):.1%}")
        if args.show:
            for name, word in status.items():
                if word in ("survived", "no tests"):
                    diff = subprocess.run(["mutmut", "show", name], cwd=work, capture_output=True, text=True)
                    print(f"--- {name} ({word})\n{diff.stdout}")
    sys.exit(0)


if __name__ == "__main__":
    main()
