"""The exported controllers' own C (everything but CasADi's generated part) is valid C99 for
every kind of export: the wrapper of a plain update, and the NMPC's preparation and feedback with
the dual QP solver (its wrapper, its QP source) and with qrqp. A syntax check with every warning an
error catches a wrong branch of the templates (a declaration for the other kind, a call to a
function this kind does not generate) in milliseconds, where the compiled closed-loop checks of
the NMPC take minutes and run only in the slow tests."""

from __future__ import annotations

import json
import subprocess

import pytest

from maglev_oc.cli import main
from maglev_oc.numerics import c_compiler

CC = c_compiler()


@pytest.mark.skipif(CC is None, reason="no C compiler")
@pytest.mark.parametrize(
    ("name", "options"),
    [("pid", []), ("nmpc", []), ("nmpc", ["--qp-solver", "qrqp"])],
    ids=["pid", "nmpc-dual", "nmpc-qrqp"],
)
def test_the_exported_sources_are_valid_c99(tmp_path, capsys, name, options):
    out = tmp_path / name
    assert main(["export", name, "--out", str(out), *options]) == 0
    capsys.readouterr()
    manifest = json.loads((out / "export.json").read_text())
    prefix = manifest["prefix"]
    own = [s for s in manifest["sources"] if s != f"{prefix}_generated.c"]
    assert f"{prefix}.c" in own
    assert (f"{prefix}_qp.c" in own) == (name == "nmpc" and not options)
    for source in own:
        run = subprocess.run(
            [CC, "-std=c99", "-Wall", "-Wextra", "-Werror", "-fsyntax-only", source],
            cwd=out,
            capture_output=True,
            text=True,
        )
        assert run.returncode == 0, (source, run.stderr[-2000:])
