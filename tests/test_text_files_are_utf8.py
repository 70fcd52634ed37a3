"""Every text file the package reads or writes is UTF-8 whatever the machine's locale.

The default text encoding is the locale's (cp1252 on many Windows machines); a design, a report's
table or a log header with "µm" or "±" written under one locale and read under another breaks. The
package's own sources are parsed (``ast``) and every ``open``, ``Path.open``, ``read_text`` and
``write_text`` call in text mode must name its encoding."""

from __future__ import annotations

import ast
import os
from pathlib import Path

import pytest

PACKAGE = Path(__file__).resolve().parents[1] / "maglev_oc"
TEXT_CALLS = {"open", "read_text", "write_text"}


def _mode(call: ast.Call, name: str) -> str | None:
    """The call's mode when it is a literal ("r" when none is given), None when it is computed."""
    if name in ("read_text", "write_text"):
        return "r"
    for kw in call.keywords:
        if kw.arg == "mode":
            return kw.value.value if isinstance(kw.value, ast.Constant) else None
    # open(path, mode) for the builtin, path.open(mode) for a Path
    position = 1 if isinstance(call.func, ast.Name) else 0
    if len(call.args) > position:
        arg = call.args[position]
        return arg.value if isinstance(arg, ast.Constant) and isinstance(arg.value, str) else None
    return "r"


def _inactive_mutant(name: str) -> bool:
    """Whether a function is one of mutmut's copies that is not running (``bench/mutation.py``
    copies every mutant of a function into its module beside the original and switches one on
    through ``MUTANT_UNDER_TEST``): only the code that runs is checked."""
    if "__mutmut_" not in name or name.endswith("__mutmut_orig"):
        return False
    return os.environ.get("MUTANT_UNDER_TEST", "").rpartition(".")[2] != name


def _calls(tree: ast.AST):
    """The calls of ``tree`` outside mutmut's inactive copies."""
    stack = [tree]
    while stack:
        node = stack.pop()
        if isinstance(node, ast.FunctionDef | ast.AsyncFunctionDef) and _inactive_mutant(node.name):
            continue
        if isinstance(node, ast.Call):
            yield node
        stack.extend(ast.iter_child_nodes(node))


def _unnamed_encodings(source: str) -> list[int]:
    """Lines of text-mode calls without ``encoding=``, in order."""
    lines = []
    for node in _calls(ast.parse(source)):
        func = node.func
        name = (
            func.id if isinstance(func, ast.Name) else func.attr if isinstance(func, ast.Attribute) else None
        )
        if name not in TEXT_CALLS:
            continue
        mode = _mode(node, name)
        if mode is not None and "b" in mode:
            continue
        if not any(kw.arg == "encoding" for kw in node.keywords):
            lines.append(node.lineno)
    return sorted(lines)


def test_the_check_sees_a_call_without_an_encoding():
    # the check itself: each form it must flag, and the binary and named forms it must let pass
    flagged = 'open(p)\nopen(p, "w")\nq.open("r")\nq.read_text()\nq.write_text(s)\n'
    passed = 'open(p, "rb")\nq.open("wb")\nq.read_text(encoding="utf-8")\nopen(p, "w", encoding="utf-8")\n'
    assert _unnamed_encodings(flagged) == [1, 2, 3, 4, 5]
    assert _unnamed_encodings(passed) == []


@pytest.mark.parametrize("path", sorted(PACKAGE.rglob("*.py")), ids=lambda p: str(p.relative_to(PACKAGE)))
def test_every_text_file_is_opened_as_utf8(path):
    assert _unnamed_encodings(path.read_text(encoding="utf-8")) == [], f"{path}: text opened without encoding"
