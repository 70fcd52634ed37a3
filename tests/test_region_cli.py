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
