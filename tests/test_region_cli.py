"""maglev-oc region."""

from __future__ import annotations

import json

from maglev_oc.cli import main


def test_region_writes_certificates(tmp_path, capsys):
    out = tmp_path / "region.json"
    assert main(["region", "--gaps", "20", "--json", str(out)]) == 0
    doc = json.loads(out.read_text())
    (rec,) = doc["certificates"]
    assert rec["certified"] and rec["binding"] == "headroom"
    # e1 semi-axis 6.06 mm at 20 mm (test_region_procedure2); 1 % from the certification ladder
    assert abs(rec["semi_axes_SI"]["e1"] - 6.06e-3) < 0.06e-3
    assert "20 mm" in capsys.readouterr().out


def test_region_rejects_millimetre_mistakes(capsys):
    assert main(["region", "--gaps", "0.02"]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "--gaps" in err[0]


# --- region --robust: the certified robust level beside the empirical one ------------------------
def _robust_json(tmp_path, capsys, *options: str) -> tuple[dict, str]:
    out = tmp_path / "robust.json"
    argv = ["region", "--robust", "--confidence", "0.5", "--samples", "20", *options, "--json", str(out)]
    assert main(argv) == 0
    return json.loads(out.read_text()), capsys.readouterr().out


def test_region_robust_certifies_25mm_and_refutes_15mm(tmp_path, capsys):
    # bench/region_robust_certificate.py: with the robust SDP's P the whole nominal level is
    # certified at 25 mm for the 0.5 confidence set, while 15 mm is refuted by a real plant
    doc, out = _robust_json(tmp_path, capsys, "--gaps", "25", "15")
    at25, at15 = (row["certified"] for row in doc["setpoints"])
    assert at25["status"] == "certified" and at25["ratio"] == 1.0  # the first rung: exactly c_nom
    assert at15["status"] == "not_certified" and at15["ratio"] == 0.0
    assert len(at15["refuting_plant"]) == 4 and 0 < at15["refuted_at_level"] <= at15["nominal_level"]
    lines = {line.split()[0]: line for line in out.splitlines() if " mm " in line}
    assert lines["25"].rstrip().endswith("1.00  certified")
    assert "not certified: refuted by plant C=(" in lines["15"]


def test_region_robust_certify_boxes_is_the_budget(tmp_path, capsys):
    # certifying 25 mm takes ~25 000 boxes: with 1000 per level no rung is decided
    doc, out = _robust_json(tmp_path, capsys, "--gaps", "25", "--certify-boxes", "1000")
    (row,) = doc["setpoints"]
    assert doc["certify_boxes"] == 1000
    assert row["certified"]["status"] == "not_certified" and row["certified"]["refuting_plant"] is None
    assert "undecided within the budget" in out
