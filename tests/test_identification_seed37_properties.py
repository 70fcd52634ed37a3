"""Properties of ``maglev_oc.identification`` written against the survivors of the seed-37 mutation-testing
run: each test states a property the code should have, not the mutated token.

* NPFSI refuses a Q or Q0 that is not a finite symmetric (Q0: positive definite) matrix with a message
  naming the argument as the caller wrote it (Q, not q or Q0);
* the eps-trend study's report gives each constant's relative change from eps = 0.001 to 0.05 in percent,
  signed, beside its direction: the papers' Table III C1 13.97 -> 16.23 is "+16.18 %" (up);
* a fit's report gives each parameter's standard error relative to its value, |s / v| in percent to the
  3 digits shown, with the parameter's unit in brackets;
* a fit's JSON gives each parameter the unit the result itself states (its ``estimates``, its report):
  C1..C4 their units, a term's parameter none;
* a PRBS design records the settings of its reference: played again with the recorded bit times and
  filter bandwidth, ``prbs_reference`` gives the design's reference (at its excursions);
* design.json says what it is (format "maglev_oc experiment design 1") and gives the predicted peak
  currents under the same names as the budget (i_q horizontal, i_d vertical, which carries the
  levitation's holding current), each within its budget and as the report prints them.
"""

from __future__ import annotations

import json
import re

import numpy as np
import pytest

from maglev_oc.errors import InputError
from maglev_oc.identification.design import (
    ExperimentDesigner,
    design_experiment,
    prbs_reference,
    write_design,
)
from maglev_oc.identification.eps_trend import FLAT_BAND, EpsTrend, EpsTrendStudy
from maglev_oc.identification.equation_error import EquationError
from maglev_oc.identification.layout import CONSTANT_NAMES, UNITS
from maglev_oc.identification.npfsi import PAPER_EPSILONS, NpfsiEstimator
from maglev_oc.model.equilibrium import equilibrium_currents
from maglev_oc.model.parameters import PAPER_CONSTANTS
from maglev_oc.regression.terms import constant_force


# --- NPFSI's matrices ----------------------------------------------------------------------------------
@pytest.mark.parametrize(
    ("kw", "message"),
    [
        ({"Q": np.array([[1.0, 0.5], [0.0, 1.0]])}, "Q must be symmetric"),
        ({"Q": np.ones((2, 3))}, "Q must be a finite square matrix, got shape (2, 3)"),
        ({"Q": np.array([[np.nan]])}, "Q must be a finite square matrix, got shape (1, 1)"),
        ({"Q0": np.array([[1.0, 0.5], [0.0, 1.0]])}, "Q0 must be symmetric"),
        ({"Q0": np.ones((2, 3))}, "Q0 must be a finite square matrix, got shape (2, 3)"),
    ],
)
def test_npfsi_names_the_matrix_it_refuses_as_the_caller_wrote_it(kw, message):
    """000's Sigma' = A'A - gamma^-2 Q needs a symmetric Q, Sigma(0) = Q0 a symmetric one; a matrix
    that is not is refused, and the message names the keyword the caller passed (Q or Q0, case as
    written), so the caller knows which of the two to fix."""
    with pytest.raises(InputError) as err:
        NpfsiEstimator(0.01, **kw)
    assert str(err.value) == message


def test_npfsi_accepts_a_symmetric_semidefinite_q():
    """Q need not be definite (the papers' default A'A is singular on data that miss a direction)."""
    q = np.array([[1.0, 1.0], [1.0, 1.0]])
    np.testing.assert_array_equal(NpfsiEstimator(0.01, Q=q).Q, q)


# --- the eps-trend study's report ----------------------------------------------------------------------
def _papers(table: str, names: tuple[str, ...]) -> EpsTrend:
    values = [[getattr(PAPER_CONSTANTS[f"{table}_eps{e:g}"], k) for e in PAPER_EPSILONS] for k in names]
    return EpsTrend(f"paper 000, {table}", names, PAPER_EPSILONS, np.array(values))


def _ours(names: tuple[str, ...], first: list[float], last: list[float]) -> EpsTrend:
    mid = [(a + b) / 2 for a, b in zip(first, last, strict=True)]
    return EpsTrend("a run", names, PAPER_EPSILONS, np.array([first, mid, last]).T)


def _study() -> EpsTrendStudy:
    t3, t2 = CONSTANT_NAMES, ("C2", "C3", "C4")
    default3 = _ours(t3, [14.0, 800.0, 30.0, 0.08], [13.44, 800.0, 29.1, 0.0804])
    default2 = _ours(t2, [790.0, 30.0, 0.1], [790.0, 29.4, 0.1015])
    return EpsTrendStudy(
        success=True,
        status="partly_reproduced",
        message="made by hand",
        papers_table2=_papers("table2", t2),
        papers_table3=_papers("table3", t3),
        default_table2=default2,
        default_table3=default3,
        friction_table2=_ours(t2, [790.0, 30.0, 0.1], [787.0, 32.1, 0.2]),
        friction_table3=_ours(t3, [14.0, 800.0, 30.0, 0.08], [16.1, 798.0, 33.0, 0.16]),
        zero_phase_table3=default3,
        limit_default_table3=default3,
        limit_friction_table3=default3,
        truth={k: 1.0 for k in t3},
        friction={"horizontal": {"coulomb": 1.0, "viscous": 10.0}},
        observer_lag=0.003,
        damping_rate=1.0,
        papers_damping=10.0,
        band=FLAT_BAND,
        explanation="none",
        timings={"total": 1.0},
    )


def test_the_eps_trend_report_gives_each_change_in_percent_beside_its_direction():
    """Each row of the report gives each constant's change from eps = 0.001 to 0.05, v(0.05) / v(0.001)
    - 1, in percent with its sign and two decimals, then its direction (flat within 1 %). The papers'
    rows, worked out by hand from 000's tables: Table III C1 13.97 -> 16.23 (+16.18 %), C2 796.93 ->
    795.01 (-0.24 %, flat), C3 30.33 -> 33.44 (+10.25 %), C4 0.06 -> 0.15 (+150.00 %); Table II C2
    790.97 -> 788.98 (-0.25 %), C3 30.47 -> 32.44 (+6.47 %), C4 0.11 -> 0.18 (+63.64 %). Our default
    rows here: C1 14 -> 13.44 (-4.00 %), C2 unchanged (+0.00 %, flat)."""
    lines = _study().report().splitlines()
    t3, t2 = (
        lines.index("  table3: relative change from eps = 0.001 to 0.05"),
        lines.index("  table2: relative change from eps = 0.001 to 0.05"),
    )
    assert (
        lines[t3 + 1]
        == "    papers    C1 +16.18 % (up), C2 -0.24 % (flat), C3 +10.25 % (up), C4 +150.00 % (up)"
    )
    assert (
        lines[t3 + 2]
        == "    default   C1 -4.00 % (down), C2 +0.00 % (flat), C3 -3.00 % (down), C4 +0.50 % (flat)"
    )
    assert lines[t2 + 1] == "    papers    C2 -0.25 % (flat), C3 +6.47 % (up), C4 +63.64 % (up)"
    assert lines[t2 + 2] == "    default   C2 +0.00 % (flat), C3 -2.00 % (down), C4 +1.50 % (up)"
    assert lines[t2 + 3] == "    friction  C2 -0.38 % (flat), C3 +7.00 % (up), C4 +100.00 % (up)"


# --- a fit's report and JSON ---------------------------------------------------------------------------
@pytest.fixture(scope="module")
def force_fit(model, twin_log):
    """Equation error on the twin's excitation, C1..C4 and a constant vertical force (a term's
    parameter, which has no entry among the constants' units)."""
    fit = EquationError(twin_log, model, terms=(constant_force(model.params, "vertical"),)).fit()
    assert fit.success, fit.message
    return fit


VARIABLE = re.compile(
    r"^    (?P<name>\S+)\s*:\s+(?P<value>\S+) \+/- (?P<stderr>\S+)\s+\((?P<rel>\S+)%\)\s+"
    r"\(init = (?P<init>\S+)\)(?:  \[(?P<unit>.+)\])?$"
)


def _variables(report: str) -> dict[str, dict[str, str]]:
    lines = report.splitlines()
    start = lines.index("[[Variables]]") + 1
    out = {}
    for line in lines[start:]:
        m = VARIABLE.match(line)
        if m is None:
            break
        out[m["name"]] = m.groupdict()
    return out


def test_a_fits_report_gives_each_relative_standard_error_in_percent(force_fit):
    """Each variable's line: the value, its standard error, the error relative to the value in
    percent, 100 |s / v|, to the 3 significant digits shown (the constants' are 0.01-1 %, the
    force's about 100 %: the twin has no constant force to find), and the unit of C1..C4 in brackets.
    Value and error are the fit's to the 7 and 4 digits printed."""
    rows = _variables(force_fit.report())
    assert list(rows) == list(force_fit.names)
    for k, row in rows.items():
        v, s = force_fit.values[k], force_fit.stderr[k]
        assert float(row["value"]) == pytest.approx(v, rel=5e-7)
        assert float(row["stderr"]) == pytest.approx(s, rel=5e-4)
        assert float(row["rel"]) == float(f"{100 * abs(s / v):.3g}"), (k, row["rel"])
        assert float(row["init"]) == force_fit.initial[k]
        assert row["unit"] == (UNITS[k] if k in CONSTANT_NAMES else None)


def test_a_fits_json_gives_each_parameter_the_unit_the_result_states(force_fit):
    """The JSON a script reads: every parameter's entry carries ``unit``, the unit of the result's own
    ``estimates`` and of the report's brackets: C1..C4 their units (C1 m/(s^2 A)). The term's force is
    in N (constant_force's parameter); the result does not state it today, and the file then says ""
    (no unit), never a placeholder: "" or "N" is right, anything else is not."""
    d = json.loads(json.dumps(force_fit.to_dict(), allow_nan=False))
    rows = _variables(force_fit.report())
    assert list(d["parameters"]) == list(force_fit.names)
    for k, entry in d["parameters"].items():
        assert entry["unit"] == force_fit.estimates[k].unit == (rows[k]["unit"] or ""), k
    for k in CONSTANT_NAMES:
        assert d["parameters"][k]["unit"] == UNITS[k] != ""
    assert d["parameters"]["C1"]["unit"] == "m/(s^2 A)"
    assert d["parameters"]["constant_force_vertical.force"]["unit"] in ("", "N")


# --- a PRBS design -------------------------------------------------------------------------------------
PRBS_SECONDS = 10.0
"""[s] The shortest design allowed (about 1 s of twin runs)."""


@pytest.fixture(scope="module")
def prbs_design(model):
    """A 10 s PRBS design on the nominal twin, in the papers' budget of the same duration."""
    return design_experiment("prbs", PRBS_SECONDS, model=model, designer=ExperimentDesigner(model))


def test_a_prbs_design_records_the_settings_its_reference_was_made_with(prbs_design):
    """The design's settings (written to design.json) are those of its reference: prbs_reference with
    the recorded bit times, filter bandwidth and seed gives the same set-points up to the excursions,
    which the budget chose. The set-points are affine in the excursion (offset + excursion x a filtered
    +-1 sequence), so the design's deviation from the offset is a multiple of the unit excursion's,
    to rounding (1e-9 relative; another bandwidth, e.g. 2 pi / 1.5 rad/s for 2 pi x 1.5, leaves a
    residual of order 1)."""
    s = prbs_design.settings
    assert s["duration_s"] == PRBS_SECONDS and s["bit_time_s"] == [0.25, 0.5]
    unit = prbs_reference(
        s["duration_s"],
        gap_amplitude=1e-3,
        position_amplitude=1e-3,
        bit_time=tuple(s["bit_time_s"]),
        bandwidth=s["filter_bandwidth_rad_s"],
        seed=s["seed"],
    )
    ref = prbs_design.reference
    np.testing.assert_array_equal(ref.t, unit.t)
    offset = np.array([0.02, 0, 0, 0, 0, 0])[:, None]  # the gap's 20 mm; the position's 0
    for rows in (slice(0, 3), slice(3, 6)):  # gap, position: each with its rate and acceleration
        x, y = (unit.values - offset)[rows].ravel(), (ref.values - offset)[rows].ravel()
        scale = float(x @ y / (x @ x))
        assert scale > 0
        assert np.linalg.norm(y - scale * x) <= 1e-9 * np.linalg.norm(y)


def test_design_json_names_itself_and_gives_peak_currents_under_their_budgets(prbs_design, model, tmp_path):
    """design.json says what it is (its format, version 1) and gives the predicted peak currents by
    current, as the budget: i_q (horizontal) and i_d (vertical), each at most its budget (the design
    is scaled into it, 1e-9 for rounding), i_d at least the holding current at 20 mm (levitation;
    i_q holds nothing). The numbers are those the report prints in A (3 decimals)."""
    path = write_design(tmp_path, prbs_design)["json"]
    d = json.loads(path.read_text())
    assert d["format"] == "maglev_oc experiment design 1"
    peak, budget = d["predicted"]["peak_current_A"], d["budget_A"]
    assert set(peak) == set(budget) == {"i_q", "i_d"}
    for k in ("i_q", "i_d"):
        assert 0 < peak[k] <= budget[k] * (1 + 1e-9), k
    hold = abs(float(equilibrium_currents(model, [0.02]).current[0]))
    assert peak["i_d"] >= hold > peak["i_q"]
    m = re.search(r"peak currents i_q (\S+) A, i_d (\S+) A \(budget (\S+) / (\S+) A\)", prbs_design.report())
    assert m, prbs_design.report()
    printed = [float(g) for g in m.groups()]
    assert printed == [round(x, 3) for x in (peak["i_q"], peak["i_d"], budget["i_q"], budget["i_d"])]
