"""Mutation testing with mutmut (the ``mutation`` extra): score per package, survivors listed.

    python bench/mutation.py                        # the five packages, 120 sampled mutants each
    python bench/mutation.py --packages region --sample 0 --show   # every mutant of one package
    python bench/mutation.py --mutate maglev_oc/region/interval.py \
        --tests tests/test_region_interval.py tests/test_region_soundness.py

mutmut 3 writes its mutants beside the sources, so ``maglev_oc/``, ``tests/`` and
``pyproject.toml`` are copied into a work folder (``bench/out/mutation/``, kept between runs so
that mutmut's map from functions to the tests that reach them is collected once). The tests are
the quick subset (``-m "not slow"``) unless ``--tests`` names files; each mutant reruns only the
tests that reach its function.

The packages hold about 12 000 mutants; running them all takes most of a day on two cores. By
default a seeded random sample of ``--sample`` mutants per package is run, and the score is
printed with its 95 % Wilson interval, so the estimate says how far it can be off. Killed and
timed-out mutants count as detected; "no tests" (a function no quick test reaches) and
"survived" count against the score. Surviving diffs go to ``survivors.txt`` in the work folder.
Not run in CI.

Each mutant's tests run in a child of mutmut's fork server (never of the process that ran the
whole suite), with one BLAS/OpenMP thread and a wall-clock limit that allows for the fixtures a
fresh process builds again (:data:`TIMEOUT_CONSTANT`); the report gives the score both with the
timeouts as detected and without them. ``--commit C`` measures commit C (default HEAD), e.g. the
tests before a change against the same sample.
"""

from __future__ import annotations

import argparse
import collections
import io
import math
import os
import random
import re
import shutil
import subprocess
import sys
import tarfile
from pathlib import Path

# One thread per numerical library in every process mutmut starts. mutmut forks a child per mutant
# from a process that has imported numpy and CasADi; a thread pool started there (OpenBLAS's, an
# OpenMP runtime's) can hold a lock at the fork, and the child then sleeps on it forever (runs of
# 2026-11-23 left children asleep with no CPU, counted as "timeout", i.e. as killed). Set before
# any subprocess starts, so it reaches pytest before numpy is imported.
THREADS = {name: "1" for name in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS")}
os.environ.update(THREADS)

ROOT = Path(__file__).resolve().parents[1]
WORK = ROOT / "bench" / "out" / "mutation"
PACKAGES = ("model", "control", "region", "identification", "diagnosis", "regression", "data", "estimation")
DETECTED = ("killed", "timeout", "segfault")
TIMEOUT_MULTIPLIER = 3.0
TIMEOUT_CONSTANT = 90.0
"""A mutant's run is stopped after TIMEOUT_MULTIPLIER x (its tests' clean duration +
TIMEOUT_CONSTANT) seconds of wall time (twice that of CPU) and counted as "timeout". mutmut's
defaults (15 x (duration + 1 s)) misjudge this suite both ways. Too short: a test's clean duration
is measured in one session, where a module or session fixture's setup is charged to the first
test that asks for it; a mutant's tests run in a fresh process and build their fixtures again
(a twin log, a diagnosis, a region certificate: 5-60 s under load), so mutants whose tests were
charged 0.02 s were stopped after 4-15 s while building them and counted as killed (15 of the
first 40 of a run of 2026-11-24). Too long: a child that hangs holds a slot for hours. 90 s covers
the largest fixture setup seen, and 3x the clean time covers a run sharing the two cores."""


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--packages", nargs="+", default=list(PACKAGES), choices=PACKAGES)
    parser.add_argument("--mutate", help="one module or package path instead of --packages")
    parser.add_argument("--tests", nargs="+", help="test files to run (default: the quick suite)")
    parser.add_argument("--sample", type=int, default=120, help="mutants per package; 0 runs all")
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument(
        "--commit", default="HEAD", help="the commit whose sources and tests are copied (default HEAD)"
    )
    parser.add_argument("--children", type=int, default=2)
    parser.add_argument("--fresh", action="store_true", help="start from a new copy of the sources")
    parser.add_argument("--show", action="store_true", help="print the surviving mutants' diffs")
    parser.add_argument("--report-only", action="store_true", help="score the last run again, run nothing")
    parser.add_argument(
        "--verify",
        action="store_true",
        help="rerun each survivor against HEAD's sources and the quick tests that import its module",
    )
    parser.add_argument("--budget", type=float, default=3600.0, help="seconds --verify may take")
    parser.add_argument(
        "--since",
        help="with --verify: the commit the run was made at (default the run's own, commit.txt; modules "
        "changed since are not rerun)",
    )
    args = parser.parse_args()
    if shutil.which("mutmut") is None:
        raise SystemExit('mutmut is missing: pip install -e ".[mutation]"')
    paths = [args.mutate] if args.mutate else [f"maglev_oc/{p}" for p in args.packages]
    if not args.report_only:
        _prepare(paths, args.tests, fresh=args.fresh, commit=args.commit)
    status = _status()
    groups = _by_package(status, paths)
    chosen = _sample(groups, args.sample, args.seed)
    if not args.report_only:
        subprocess.run(["mutmut", "run", "--max-children", str(args.children), *chosen], cwd=WORK)
        status = _status()
    left = [n for n in chosen if status.get(n) in ("survived", "no tests")]
    if args.verify:
        killed = _verify(left, args.budget, args.since)
        status.update({n: "killed" for n in killed})
        left = [n for n in left if n not in killed]
    diffs = {n: _diff(n) for n in left}
    equivalent = {n: why for n in left if (why := _equivalent(n, diffs[n]))}
    _report(groups, chosen, status, equivalent)
    survivors = [n for n in left if n not in equivalent]
    text = "".join(f"--- {n} ({status[n]})\n{diffs[n]}\n" for n in survivors)
    (WORK / "survivors.txt").write_text(text)
    listed = "".join(f"{n}: {why}\n" for n, why in sorted(equivalent.items()))
    (WORK / "equivalent.txt").write_text(listed)
    print(f"surviving diffs: {WORK / 'survivors.txt'}; equivalent, with reasons: {WORK / 'equivalent.txt'}")
    if args.show:
        print(text)


def _prepare(paths: list[str], tests: list[str] | None, *, fresh: bool, commit: str = "HEAD") -> None:
    """Copy the sources into WORK and let mutmut generate the mutants and its test map."""
    sha = subprocess.run(["git", "rev-parse", commit], cwd=ROOT, capture_output=True, text=True).stdout
    previous = (WORK / "commit.txt").read_text() if (WORK / "commit.txt").is_file() else sha
    # Another commit's sources need new mutants: mutmut regenerates a file's mutants only when the
    # source is newer than them, and the extracted sources carry their commit's time (git archive),
    # usually older than mutants made earlier today, so the old commit's mutants would be run
    if (fresh or previous != sha) and WORK.exists():
        shutil.rmtree(WORK)
    WORK.mkdir(parents=True, exist_ok=True)
    # the committed sources (HEAD or --commit), not the work tree: the score belongs to a commit,
    # and edits made while the run goes on do not reach it
    _extract(commit)
    (WORK / "commit.txt").write_text(sha)
    sources = ", ".join(f'"{p}"' for p in paths)
    selection = ", ".join(f'"{t}"' for t in tests) if tests else '"tests/"'
    # tests that read the sources as text (exports, README commands) see mutmut's trampolines
    # one process (-n 0): mutmut's trampolines and test map live in the pytest process.
    # The interrupt test sends SIGINT 3 s after starting the CLI, "past the imports": with
    # control/ mutated the trampolined sources take longer than that to import (2026-11-24, load
    # 3), the child dies inside an import and the test fails without any mutant, which stops
    # mutmut's test map (it runs with -x)
    quick = (
        ""
        if tests
        else ', "-m", "not slow", "--ignore=tests/test_house.py", "--ignore=tests/test_readme.py", '
        '"--deselect=tests/test_bad_input.py::test_interrupt_ends_with_one_line_and_130"'
    )
    marker = f'pytest_add_cli_args = ["-n", "0", "-p", "no:cacheprovider"{quick}]\n'
    config = (
        "\n[tool.mutmut]\n"
        f"source_paths = [{sources}]\n"
        f"pytest_add_cli_args_test_selection = [{selection}]\n"
        f"{marker}"
        'also_copy = ["tests/", "maglev_oc/", "bench/"]\n'
        # the mutants run in children of a fork server that has only collected the tests, not of
        # the process that ran the whole suite to map tests to functions (its Dask clusters, event
        # loops and thread pools are not inherited)
        'process_isolation = "forkserver"\n'
        # the limits of a mutant's run (see TIMEOUT_CONSTANT)
        f"timeout_multiplier = {TIMEOUT_MULTIPLIER}\n"
        f"timeout_constant = {TIMEOUT_CONSTANT}\n"
    )
    (WORK / "pyproject.toml").write_text((ROOT / "pyproject.toml").read_text() + config)
    # A pattern that matches no mutant: mutmut generates the mutants and collects which tests
    # reach which function, then stops before running any mutant.
    subprocess.run(["mutmut", "run", "no-such-mutant-*"], cwd=WORK, capture_output=True)


def _extract(commit: str) -> None:
    """The package and tests of ``commit`` into WORK (replacing the copies there)."""
    for name in ("maglev_oc", "tests", "bench"):
        if (WORK / name).exists():
            shutil.rmtree(WORK / name)
    # the C harness the code generation reads from a source checkout (codegen.REPO_HARNESS,
    # ROOT/bench/nmpc_c): quick tests read it too, and without it they fail without any mutant,
    # which stops mutmut's test map (a run of 2026-11-24 collected no stats)
    extra = [
        path
        for path in ("bench/nmpc_c",)
        if subprocess.run(["git", "cat-file", "-e", f"{commit}:{path}"], cwd=ROOT).returncode == 0
    ]
    archive = subprocess.run(
        ["git", "archive", "--format=tar", commit, "maglev_oc", "tests", "analyses", *extra],
        cwd=ROOT,
        capture_output=True,
        check=True,
    ).stdout
    with tarfile.open(fileobj=io.BytesIO(archive)) as tar:
        tar.extractall(WORK, filter="data")
    # the analyses ship as maglev_oc.analyses (an editable install maps them to ROOT/analyses):
    # inside the copied package they are found first
    shutil.move(WORK / "analyses", WORK / "maglev_oc" / "analyses")


def _status() -> dict[str, str]:
    out = subprocess.run(
        ["mutmut", "results", "--all", "true"], cwd=WORK, capture_output=True, text=True
    ).stdout
    status = {}
    for line in out.splitlines():
        name, _, word = line.strip().rpartition(": ")
        if name:
            status[name] = word
    return status


def _by_package(status: dict[str, str], paths: list[str]) -> dict[str, list[str]]:
    groups: dict[str, list[str]] = {}
    for path in paths:
        prefix = path.removesuffix(".py").replace("/", ".")
        groups[path] = sorted(n for n in status if n == prefix or n.startswith(prefix + "."))
    return groups


def _sample(groups: dict[str, list[str]], size: int, seed: int) -> list[str]:
    rng = random.Random(seed)
    chosen = []
    for names in groups.values():
        chosen += names if size <= 0 or size >= len(names) else rng.sample(names, size)
    return chosen


def _report(
    groups: dict[str, list[str]], chosen: list[str], status: dict[str, str], equivalent: dict[str, str]
) -> None:
    """Per package: mutants, sampled, detected, equivalent, score = detected / (run - equivalent)."""
    picked = set(chosen)
    detected_all = total_all = 0.0
    head = f"{'package':<30}{'mutants':>8}{'run':>5}{'killed':>7}{'equiv':>6}{'score':>7}   95 % interval"
    print("\n" + head)
    for path, names in groups.items():
        run = [n for n in names if n in picked]
        counts = collections.Counter(status.get(n, "not checked") for n in run)
        detected = sum(counts[w] for w in DETECTED)
        n_eq = sum(n in equivalent for n in run)
        # a run stopped early leaves mutants "not checked": they count neither way
        judged = max(len(run) - n_eq - counts["not checked"], 1)
        low, high = _wilson(detected, judged)
        # a timeout is a mutant that made its tests loop, or a child that hung for another reason:
        # the score without them is the bound that does not rely on the timeouts being real
        strict = (detected - counts["timeout"]) / judged
        print(
            f"{path:<30}{len(names):>8}{len(run):>5}{detected:>7}{n_eq:>6}{detected / judged:>7.1%}"
            f"   {low:.1%} - {high:.1%}   ({', '.join(f'{k} {v}' for k, v in sorted(counts.items()))};"
            f" {strict:.1%} with timeouts as survivors)"
        )
        # each package weighted by its number of mutants for the overall estimate
        if run:
            detected_all += detected / judged * len(names)
            total_all += len(names)
    overall = detected_all / max(total_all, 1)
    print(f"{'overall (weighted by mutants)':<30}{int(total_all):>8}{'':>25}{overall:>7.1%}")


def _imports(text: str, module: str) -> bool:
    """Whether a test's source names ``module`` (a.b.c): its dotted name anywhere (an import, a
    monkeypatch target), or ``from a.b import ..., c, ...`` (one line or parenthesized)."""
    if module in text:
        return True
    parent, leaf = module.rsplit(".", 1)
    names = rf"(\([^)]*\b{leaf}\b[^)]*\)|[^\n(]*\b{leaf}\b)"
    return re.search(rf"from {re.escape(parent)} import {names}", text) is not None


def _verify(names: list[str], budget: float, since: str | None) -> set[str]:
    """Survivors killed when rerun against the committed sources and quick tests (HEAD).

    mutmut runs for each mutant only the tests it saw reach the mutated function; a function
    first reached inside a session fixture is attributed to whichever test built the fixture,
    so a test that uses the fixture later is not rerun and the mutant is reported as surviving;
    and tests written after the run are not in its map. Here the work copy takes HEAD's sources
    and tests (as a run does: not the work tree, where others' edits may be half done), each
    survivor is applied to it and the test files that import its module (or its package) run,
    stopping at the first failure; the file is restored after each. A survivor in a module
    changed since the run is left as it is (its mutant was made from the old code). Stops after
    ``budget`` seconds."""
    import time

    since = since or (WORK / "commit.txt").read_text().strip()
    diff = subprocess.run(
        ["git", "diff", "--name-only", since, "HEAD", "--", "maglev_oc"],
        cwd=ROOT,
        capture_output=True,
        text=True,
    )
    changed = {".".join(Path(p).with_suffix("").parts) for p in diff.stdout.split()}
    _extract("HEAD")
    killed = set()
    clean: dict[tuple, bool] = {}
    # tests that read the repository's files (README, exports) are not about a mutant's effect
    tests = [
        t
        for t in sorted((WORK / "tests").glob("test_*.py"))
        if t.name not in ("test_house.py", "test_readme.py")
    ]
    t0 = time.perf_counter()
    for name in names:
        module = re.sub(r"\.x.*$", "", name)  # maglev_oc.pkg.module
        package = ".".join(module.split(".")[:2])
        source = WORK / (module.replace(".", "/") + ".py")
        if module in changed or not source.is_file():
            print(f"{name}: not rerun (its module changed since the run)")
            continue
        if time.perf_counter() - t0 > budget:
            print("verify: budget spent")
            break
        # the test files that import the mutated module, else those that import its package
        files = [str(t.relative_to(WORK)) for t in tests if _imports(t.read_text(), module)]
        files = files or [str(t.relative_to(WORK)) for t in tests if package in t.read_text()]
        pytest = [
            sys.executable,
            "-m",
            "pytest",
            "-n",
            "0",
            "-x",
            "-q",
            "-m",
            "not slow",
            "-p",
            "no:cacheprovider",
            *files,
        ]
        env = {**os.environ, "PYTHONPATH": str(WORK)}
        key = tuple(files)
        if key not in clean:  # the same files pass without the mutant (else a failure says nothing)
            clean[key] = subprocess.run(pytest, cwd=WORK, capture_output=True, env=env).returncode == 0
        if not clean[key]:
            print(f"{name}: not rerun (its test files fail without the mutant)")
            continue
        original = source.read_text()
        try:
            subprocess.run(["mutmut", "apply", name], cwd=WORK, capture_output=True)
            run = subprocess.run(pytest, cwd=WORK, capture_output=True, env=env)
            if run.returncode != 0:
                killed.add(name)
            print(
                f"{name}: {'killed' if run.returncode else 'survived'} ({len(files)} test files)", flush=True
            )
        finally:
            source.write_text(original)
    return killed


EQUIVALENT_FILE = ROOT / "bench" / "mutation_equivalent.txt"
"""Mutants judged equivalent by reading them: ``name: reason`` per line (function-level names, so
a list stays valid while the function is unchanged)."""

_STRING = re.compile(r"'[^']*'|\"[^\"]*\"")


def _equivalent(name: str, diff: str) -> str | None:
    """Why a surviving mutant cannot change a result (or None): the listed reasons, or a change
    confined to the text of a label — a CasADi Function's name or its inputs' and outputs' names
    (nothing looks them up), or the words of an error message (its type and the value it names
    are what tests check)."""
    if EQUIVALENT_FILE.is_file():
        for line in EQUIVALENT_FILE.read_text().splitlines():
            key, _, why = line.partition(": ")
            if key.strip() == name:
                return why.strip()
    minus = [ln[1:] for ln in diff.splitlines() if ln.startswith("-") and not ln.startswith("---")]
    plus = [ln[1:] for ln in diff.splitlines() if ln.startswith("+") and not ln.startswith("+++")]
    if len(minus) != 1 or len(plus) != 1 or _STRING.sub('""', minus[0]) != _STRING.sub('""', plus[0]):
        return None
    if re.search(r"ca\.Function\(|nlpsol\(|qpsol\(|\.sym\(", minus[0]):
        return "label: a CasADi Function's or symbol's name (nothing looks it up)"
    if re.search(r"raise \w+|Error\(|warnings\.warn|message=", minus[0]):
        return "text of a message (tests check the error's type and what it names)"
    return None


def _wilson(k: int, n: int, z: float = 1.96) -> tuple[float, float]:
    if n == 0:
        return 0.0, 1.0
    p = k / n
    centre = (p + z * z / (2 * n)) / (1 + z * z / n)
    half = z * math.sqrt(p * (1 - p) / n + z * z / (4 * n * n)) / (1 + z * z / n)
    return max(centre - half, 0.0), min(centre + half, 1.0)


def _diff(name: str) -> str:
    out = subprocess.run(["mutmut", "show", name], cwd=WORK, capture_output=True, text=True).stdout
    return re.sub(r"^# .*\n", "", out)


if __name__ == "__main__":
    main()
    sys.exit(0)
