"""Properties of the controllers that the seed-37 mutation run found untested.

Each test checks what a user of ``maglev_oc/control/`` relies on:

- an exported controller's README describes the code that was exported: a controller without
  a QP (the PID, the FL regulator) has no "The QP solver" section and never mentions a QP
  solver it does not contain (CasADi's qrqp, the dual active-set method), and its manifest says
  there is no QP solver. The README is what the rig's engineer reads to build the code: a
  section on qrqp for a PID would send them looking for a QP in a file that has none.
"""

from __future__ import annotations

import json

import pytest

from maglev_oc.control.export import export_controller
from maglev_oc.control.registry import build_controller


@pytest.mark.parametrize("name", ["pid", "fl"])
def test_the_readme_of_a_controller_without_a_qp_describes_no_qp_solver(model, tmp_path, name):
    """Whatever ``qp_solver`` is passed (it is ignored for a controller that is not the NMPC,
    export_controller's docstring), the README has no QP-solver section and names neither
    solver, the sources are the controller's file and its generated file only, and the
    manifest's ``qp_solver`` is null."""
    ctrl = build_controller(name, model)
    for solver in ("dual", "qrqp"):
        out = tmp_path / f"{name}-{solver}"
        export_controller(ctrl, out, qp_solver=solver)
        readme = (out / "README.md").read_text()
        manifest = json.loads((out / "export.json").read_text())
        assert manifest["qp_solver"] is None and manifest["qp_iterations"] is None
        prefix = manifest["prefix"]
        assert manifest["sources"] == [f"{prefix}.c", f"{prefix}_generated.c"]
        assert "### The QP solver" not in readme
        assert "qrqp" not in readme.lower() and "dual active" not in readme.lower()
        assert readme.startswith(f"# {ctrl.name}, exported by maglev_oc\n")
