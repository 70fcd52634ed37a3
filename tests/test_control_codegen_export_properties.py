"""Properties of the generated code and the exported controllers (``maglev_oc.control.codegen``,
``export``), checked against files built here byte by byte and replays of the controller:

- without a C compiler, compiling says there is none (a SolverError naming $CC);
- ``read_outputs`` reads the documented instance layout, and a recorded NMPC instance replayed
  through ``rti_step`` is the call the controller made (its current and next memory);
- the exported README documents every entry point and diagnostic of the NMPC, the QP status
  codes among them, and a controller without a QP describes no QP solver.
"""

from __future__ import annotations

import json
import struct
from types import SimpleNamespace

import numpy as np
import pytest

from maglev_oc.control import codegen
from maglev_oc.control.codegen import RecordedInstances, evaluate_instances, instance_row
from maglev_oc.control.export import export_controller
from maglev_oc.control.export_qp import STATUS_CODES
from maglev_oc.control.nmpc import NonlinearMPC
from maglev_oc.control.registry import build_controller
from maglev_oc.errors import SolverError
from tests._control_cases import _equilibrium_current

GAP = 0.020  # [m] a scheduled gap (8 mm + 24 x 0.5 mm)


# --- recorded instances -------------------------------------------------------------------------
def test_a_recorded_instance_is_the_call_the_controller_makes(model):
    """Per sample k: the row recorded before ``control(k, y, reference)``, replayed through
    ``rti_step``, gives that call's current and next memory. The reference moves (a parabola in
    the horizontal position), so its node references differ from sample to sample. Same
    Function, same arithmetic: bit for bit."""
    ctrl = NonlinearMPC(model)
    n = 400
    ts = ctrl.sample_time
    reference = np.zeros((6, n))
    reference[0] = GAP
    t = ts * np.arange(n)
    reference[3], reference[4], reference[5] = 10.0 * t**2, 20.0 * t, 20.0  # m, m/s, m/s^2
    ctrl.reset([GAP, 0.0], reference[:, 0], [0.0, _equilibrium_current(model)])
    for k in range(6):
        y = np.array([GAP + 1e-5 * k, 2e-6 * k])
        inst = RecordedInstances.of(ctrl, [instance_row(ctrl, k, y, reference)])
        u_replayed, memory_replayed, _ = evaluate_instances(ctrl.rti_step, inst)
        u, _ = ctrl.control(k, y, reference)
        np.testing.assert_array_equal(u_replayed[0], u)
        np.testing.assert_array_equal(memory_replayed[0], ctrl.memory)


# --- the exported NMPC's README ------------------------------------------------------------------
def test_the_exported_nmpcs_readme_documents_its_interface_and_diagnostics(model, tmp_path):
    from maglev_oc.sim.compiled_nmpc import CompiledNMPC

    nmpc = NonlinearMPC(model, preview=False)
    export = export_controller(CompiledNMPC(nmpc, backend="vm"), tmp_path / "nmpc")
    assert export.qp_solver == "dual"
    readme = (tmp_path / "nmpc" / "README.md").read_text()
    # how to call it: every entry point the export has, the split's prepare / prepare_for /
    # feedback among them, the restart and the memory's size for hosts that allocate it
    calls = ("init", "reset", "step", "prepare", "prepare_for", "feedback")
    assert set(calls) | {"mem_size"} == set(export.entry_points)
    for entry in calls:
        assert f"{export.prefix}_{entry}(&m" in readme, entry
    assert f"{export.prefix}_mem_size()" in readme
    # every diagnostic row with its meaning; the dual solver's qp_status its status codes
    rows = {}
    for line in readme.split("## Diagnostics", 1)[1].splitlines():
        if line.startswith("| ") and "| `" in line:
            _, row, name, meaning, _ = (part.strip() for part in line.split("|"))
            rows[name.strip("`")] = (int(row), meaning)
    assert [rows[n][0] for n in export.diag_names] == list(range(len(export.diag_names)))
    assert all(rows[n][1] for n in export.diag_names)
    for code, text in STATUS_CODES.items():
        assert f"{code}: {text}" in rows["qp_status"][1]
    assert "else the QP solver's steps" in rows["qp_iterations"][1]  # counted in C, unlike Python


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


# --- the C compiler --------------------------------------------------------------------------------------
def test_compiling_without_a_c_compiler_says_there_is_none(monkeypatch, tmp_path):
    """No compiler found: both the shared library and the harness refuse with a SolverError whose
    message names the missing C compiler and how to provide one ($CC)."""
    monkeypatch.setattr(codegen, "c_compiler", lambda: None)
    code = SimpleNamespace(source=tmp_path / "x.c", include_dirs=(), link_flags=())
    for build in (codegen.compile_shared, codegen.build_harness):
        with pytest.raises(SolverError) as info:
            build(code)
        text = str(info.value)
        assert "no C compiler found" in text and "$CC" in text, text


# --- the harness's output file ---------------------------------------------------------------------------
def test_read_outputs_reads_the_documented_layout(tmp_path):
    """A file written here in the module docstring's layout (magic, n, n_in, n_out, nnz_in, nnz_out,
    then float64 rows): three outputs of widths 2, 4 and 1 over three rows come back as three arrays
    of those widths with the rows' values, bit for bit (the header's two input widths, which the
    outputs do not need, are skipped)."""
    n, nnz_in, nnz_out = 3, (5, 7), (2, 4, 1)
    rows = np.arange(n * sum(nnz_out), dtype=float).reshape(n, -1) * 0.5 - 3.25
    path = tmp_path / "out.bin"
    path.write_bytes(
        b"NMPCREC1"
        + struct.pack("<3i", n, len(nnz_in), len(nnz_out))
        + struct.pack("<2i", *nnz_in)
        + struct.pack("<3i", *nnz_out)
        + rows.astype("<f8").tobytes()
    )
    got = codegen.read_outputs(path)
    assert [g.shape for g in got] == [(3, 2), (3, 4), (3, 1)]
    np.testing.assert_array_equal(np.concatenate(got, axis=1), rows)
