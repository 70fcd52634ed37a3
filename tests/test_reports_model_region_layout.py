"""The model and operating-region reports read as a scorecard: no near-empty page, no internal
identifiers in the text, and every scorecard value recomputed here by another route than the one
the report took (roots of the dynamics instead of the closed-form equilibrium, SciPy's pole
placement instead of Ackermann's formula, the closed-loop engine instead of the batch Monte Carlo,
a step response instead of the matrix-exponential sweep).

The region study is the QUICK configuration, computed once for the module (about 15 s)."""

from __future__ import annotations

import dataclasses
import math
import re

import numpy as np
import pytest
from scipy.optimize import brentq, minimize_scalar
from scipy.signal import place_poles

from maglev_oc.control.gains import OMEGA0, PAPER_GAINS, augmented_axis
from maglev_oc.numerics import c_compiler

BACKEND = "c" if c_compiler() is not None else "vm"
"""The engine's own C loop (not the Monte Carlo's batch runner) when there is a compiler."""

# Words the reports must not print: code identifiers instead of plain words.
IDENTIFIERS = re.compile(
    r"mapaccum|TwinEffects|table[23]_eps|_retuned|closed_form|headroom|gap_low|gap_high|position_low|"
    r"position_high|[A-Za-z_]+\(\)|\b[a-z]{3,}_[a-z]{3,}\b"
)
NUMBER = re.compile(r"[−-]?\d+(?:\.\d+)?(?:e[+-]?\d+)?")


def _numbers(text: str) -> list[float]:
    return [float(x.replace("−", "-")) for x in NUMBER.findall(text.replace(",", " ").replace("±", " "))]


@pytest.fixture(scope="module")
def model_report(shared_model_report):
    """reports/model.pdf: (study, contents), written once per session (tests/report_support.py)."""
    return shared_model_report


@pytest.fixture(scope="module")
def region_report(shared_region_report):
    """The QUICK operating-region study and its report: (study, contents), computed once per
    session (tests/report_support.py; tests/test_region_study.py checks the same study)."""
    return shared_region_report


class _Rows(dict):
    """Scorecard rows by claim, the cells' line breaks undone; ``rows[prefix]`` is the only row
    whose claim starts with ``prefix``."""

    def __getitem__(self, prefix: str):
        found = [row for claim, row in self.items() if claim.startswith(prefix)]
        assert len(found) == 1, (prefix, list(self))
        return found[0]


def _scorecard(contents):
    table = contents.sections[0]
    assert contents.headings[0].startswith("Scorecard") and table.columns[0] == "claim (source)"
    flat = [tuple(" ".join(cell.split()) for cell in row) for row in table.rows]
    return _Rows({row[0]: row for row in flat}), table


# --- layout -------------------------------------------------------------------------------------------
@pytest.mark.parametrize("which", ["model_report", "region_report"])
def test_no_near_empty_page_and_no_identifiers(which, request):
    _, contents = request.getfixturevalue(which)
    assert contents.sparse_pages() == []
    assert contents.pages[0].heading.startswith("Scorecard")
    assert contents.pages[-1].heading.startswith("Appendix")
    found = sorted(set(IDENTIFIERS.findall(contents.text())))
    assert found == [], found


# --- the model report's scorecard ------------------------------------------------------------------------
def test_model_equilibrium_currents_are_roots_of_the_dynamics(model_report, model):
    from maglev_oc.analyses.model import SPEC_EQUILIBRIA

    _study, contents = model_report
    rows, _ = _scorecard(contents)
    row = rows["Equilibrium current i_d at i_q = 0"]
    printed = _numbers(row[2])
    # gap x2' = 0 at rest with i_q = 0: the small root in i_d of the model's own dynamics
    for (gap, spec), shown in zip(SPEC_EQUILIBRIA, printed, strict=True):

        def accel(i_d, gap=gap):
            return float(model.dynamics([gap, 0, 0, 0], [0.0, i_d])[1, 0])

        root = brentq(accel, -9.0, 9.0, xtol=1e-12)
        assert shown == pytest.approx(root, abs=0.005)  # printed to 0.01 A
        assert ("reproduced" in row[3]) == (abs(root - spec) <= 0.05)
    # zero current: the gap where the magnets' pull alone balances gravity
    zero = brentq(lambda g: float(model.dynamics([g, 0, 0, 0], [0.0, 0.0])[1, 0]), 0.015, 0.035, xtol=1e-12)
    assert _numbers(rows["i_d crosses zero (SPEC 1)"][2])[0] == pytest.approx(zero * 1e3, abs=0.005)


def _char_poly_roots(k) -> np.ndarray:
    """Roots of (s^2 - k2 s - k1)(s^3 + w^2 s) - (k5 s^2 + k4 s + k3), written out by hand."""
    k1, k2, k3, k4, k5 = k
    w2 = OMEGA0**2
    coeffs = np.polysub(np.polymul([1.0, -k2, -k1], [1.0, 0.0, w2, 0.0]), [k5, k4, k3])
    return np.roots(coeffs)


def test_model_gains_and_their_poles_by_another_route(model_report):
    _study, contents = model_report
    rows, _ = _scorecard(contents)
    a, b = augmented_axis(OMEGA0)
    for name, paper in PAPER_GAINS.items():
        # SciPy's pole placement (u = -K x) instead of the report's Ackermann formula
        ours = -place_poles(a, b, np.asarray(paper.poles, dtype=complex)).gain_matrix.ravel()
        key = {"K_h": "K_h (", "K_v": "K_v (", "K_v_retuned": "K_v retuned"}[name]
        shown = _numbers(rows[key][2])
        # printed to 0.01; place_poles' own error grows with the five poles' spread (1e-7 relative)
        np.testing.assert_allclose(shown, ours, atol=0.006, rtol=1e-6)
        worst = np.max(np.abs(np.asarray(paper.printed) - ours) / np.abs(ours))
        assert f"{worst:.2%}" in rows[key][3] or f"{worst:.1%}" in rows[key][3]
    for name in ("K_h", "K_v"):
        roots = _char_poly_roots(PAPER_GAINS[name].printed)
        shown = _numbers(rows[f"The printed {name} places its poles"][2])
        expected = sorted(
            {round(abs(r.real), 2) for r in roots} | {round(abs(r.imag), 2) for r in roots} - {0.0}
        )
        assert sorted(round(abs(x), 2) for x in shown) == pytest.approx(expected, abs=0.051)  # 3 digits
        design = np.asarray(PAPER_GAINS[name].poles, dtype=complex)
        move = max(np.min(np.abs(roots - p)) for p in design)
        assert f"up to {move:.2g} 1/s" in rows[f"The printed {name} places its poles"][3]


def test_model_note_counts_truncated_and_rounded_entries(model_report):
    study, contents = model_report
    _, table = _scorecard(contents)
    counts = {"exact": 0, "truncated": 0, "rounded": 0, "either": 0, "neither": 0}
    for c in study.gains:
        if c.paper.name == "K_v_retuned":
            continue
        for p, v in zip(c.paper.printed, c.computed, strict=True):
            t, r = float(np.trunc(v)), float(np.floor(v + 0.5))
            if v == r:
                counts["exact"] += 1
            elif p == t == r:
                counts["either"] += 1
            elif p == t:
                counts["truncated"] += 1
            elif p == r:
                counts["rounded"] += 1
            else:
                counts["neither"] += 1
    note = table.notes[0]
    for kind, words in (
        ("exact", "are exact integers"),
        ("truncated", "truncated toward zero"),
        ("rounded", "rounded to the nearest"),
        ("either", "truncated or rounded alike"),
        ("neither", "match neither"),
    ):
        if counts[kind]:
            assert re.search(rf"\b{counts[kind]} (are ours |are |match )?[a-z ]*{words}", note), (kind, note)
        else:
            assert words not in note
    # the finding: not all of them are truncations
    assert counts["rounded"] >= 1 and counts["truncated"] >= 1


def test_printing_kind_closed_form_cases():
    from maglev_oc.analyses.model import printing_kind

    assert printing_kind(-1182, -1182.79) == "truncated"
    assert printing_kind(-11924, -11923.64) == "rounded"
    assert printing_kind(-45128, -45128.17) == "either"
    assert printing_kind(-55, -55.0) == "exact"
    assert printing_kind(-103350, -103348.996) == "neither"
    assert printing_kind(7, 6.5) == "rounded"  # half rounds away from zero upward, not to even


# --- the operating-region report's scorecard ------------------------------------------------------------
def test_region_current_on_r_zero_is_the_largest_vertical_pull(region_report, model):
    study, contents = region_report
    rows, _ = _scorecard(contents)
    lo, hi = study.feasible.gap_range
    # R = 0 where the transformation asks for the largest x2' (gap-opening acceleration) any i_d can
    # give: find that i_d by maximising the model's own x2' (not from -L3 / (2 L4))
    currents = []
    for gap in np.linspace(lo, hi, 23):
        res = minimize_scalar(
            lambda i_d, gap=gap: -float(model.dynamics([gap, 0, 0, 0], [0.0, i_d])[1, 0]),
            bounds=(0.0, 200.0),
            method="bounded",
            options={"xatol": 1e-6},
        )
        currents.append(abs(res.x))
    shown = float(re.search(r"\|u\| >= ([\d.]+) A", rows["The transformation exists where"][2]).group(1))
    assert shown == pytest.approx(min(currents), abs=0.06)  # printed to 0.1 A; grid 1 mm
    assert ("differs" in rows["The transformation exists where"][3]) == (min(currents) > 9.0)


def test_region_certified_rectangle_fits_its_set(region_report):
    study, contents = region_report
    rows, _ = _scorecard(contents)
    row = rows["Certified starts at rest"]
    mid = min(
        (r for r in study.references if r.reference.is_setpoint), key=lambda r: abs(r.reference.gap - 0.02)
    )
    for cert, (a1, a2) in ((mid.best, _numbers(row[2])[0:2]), (mid.lyapunov, _numbers(row[2])[2:4])):
        # the corners of the printed box (V is convex: its largest value on the box is at a corner)
        # lie on the certified level to the printed 3 digits; 1 % wider they are outside
        corners = [(s1 * a1, s2 * a2) for s1 in (1, -1) for s2 in (1, -1)]
        v = [
            cert.P[0, 0] * x**2 + 2 * cert.P[0, 5] * x * y + cert.P[5, 5] * y**2
            for x, y in (np.array(corners) / 1e3)
        ]
        assert max(v) <= cert.level * 1.005
        assert max(v) * 1.01**2 > cert.level
    n = sum(c.n for r in study.references for c in r.checks.values())
    bad = sum(int(c.violating.sum()) for r in study.references for c in r.checks.values())
    assert f"{n} runs inside" in row[3] and f"{bad} left F" in row[3]


def test_region_large_step_runs_agree_with_the_engine(region_report, model):
    """The large step on the closed-loop engine (one run, its own initial state and loop), not the
    batch Monte Carlo: the FL regulator's largest current and the linear regulator's least gap."""
    from maglev_oc.control.fl_regulator import FeedbackLinearizingRegulator
    from maglev_oc.control.linear_regulator import paper_linear_regulator
    from maglev_oc.sim.engine import ClosedLoop
    from maglev_oc.sim.scenarios import paper_scenarios
    from maglev_oc.sim.twin import RigTwin

    _study, contents = region_report
    rows, _ = _scorecard(contents)
    scenario = dataclasses.replace(paper_scenarios()["large_step"], duration=3.0)
    fl = ClosedLoop(RigTwin(model), FeedbackLinearizingRegulator(model), backend=BACKEND).run(scenario)
    lin = ClosedLoop(RigTwin(model), paper_linear_regulator(model), backend=BACKEND).run(scenario)
    fl_row = rows["The FL regulator settles the"]
    assert _numbers(fl_row[2])[-1] == pytest.approx(np.max(np.hypot(*fl.u)), abs=0.05)  # 0.1 A printed
    lin_row = rows["The linear regulator goes"]
    assert _numbers(lin_row[2])[0] == pytest.approx(np.min(lin.x[0]) * 1e3, abs=0.05)  # 3 digits
    assert fl.success and lin.success and "differs" in lin_row[3]


def test_region_overshoot_and_stopper_prediction_from_a_step_response(region_report):
    """The FL loop's overshoot from SciPy's step response of the vertical axis (A + B K_v), and the
    stopper hits it predicts, against the scorecard and the sampled basin."""
    from scipy.signal import StateSpace, step

    from maglev_oc.region.study import BASIN_OUTCOMES

    study, contents = region_report
    rows, _ = _scorecard(contents)
    ls = study.large_step
    a, b = augmented_axis(OMEGA0)
    out = {}
    for axis, gains in (("v", study.loop.K_v), ("h", study.loop.K_h)):
        acl = a + b @ np.asarray(gains).reshape(1, 5)
        # the error after a unit error at rest is the response to the initial state e = 1
        _, y = step(
            StateSpace(acl, np.zeros((5, 1)), np.eye(5)[:1], [[0.0]]),
            X0=np.eye(5)[0],
            T=np.linspace(0, 10, 20001),
        )
        out[axis] = (float(np.min(y)), float(np.max(y)))
    row = rows["The FL regulator's range exceeds"]
    assert f"({-out['v'][0]:.0%})" in row[3]
    lo, hi = study.feasible.gap_range
    p_lo, p_hi = study.feasible.position_range
    hits = np.zeros_like(ls.predicted_stopper)
    for j, s in enumerate(ls.map_starts):
        for i, t in enumerate(ls.sweep_targets):
            gaps = [t + (s - t) * out["v"][0], t + (s - t) * out["v"][1]]
            pos = [ls.target_position - ls.target_position * e for e in out["h"]]
            hits[i, j] = min(gaps) <= lo or max(gaps) >= hi or min(pos) <= p_lo or max(pos) >= p_hi
    np.testing.assert_array_equal(hits, ls.predicted_stopper)
    fl_hits = ls.maps["FL regulator"]["outcome"] == BASIN_OUTCOMES.index("stopper")
    assert f"{int(np.sum(hits & fl_hits))} of the FL's {int(fl_hits.sum())}" in row[3]
    fl, li = ls.maps["FL regulator"], ls.maps["linear regulator"]
    for d, name in ((fl, "FL"), (li, "linear")):
        assert f"{name} {100 * np.mean(d['success']):.0f} %" in row[2]
    assert math.isclose(np.mean(fl["success"]), np.mean(fl["within_limit"]))  # FL must stay in F anyway


def test_region_robust_row_recomputed_from_the_runs(region_report):
    """The robust page's 0.95 row and its box row from the runs' own arrays: which runs left F by
    F's definition (not the sweep's flag), the plants inside the chi-square ellipsoid of the
    covariance (written out here) or the box of the papers' Tables II-III, the starts inside the
    certified sets; the text's counts and the scorecard's against them."""
    from scipy.stats import chi2

    from maglev_oc.model.parameters import PAPER_CONSTANTS

    study, contents = region_report
    rb = study.robust
    table = contents.section("Per set-point: runs that left F")
    text = " ".join(" ".join(p.split()) for p in contents.section("Robust to the plant").paragraphs)
    limit = study.feasible.current_limit
    c0 = np.asarray(study.robust.rows[0].sweep.spec.constants)
    cov = np.asarray(rb.covariance)
    assert rb.assumed and "ASSUMED" in text
    # the assumed covariance: 2/2/2/10 % standard errors of C1..C4
    np.testing.assert_allclose(np.sqrt(np.diag(cov)) / c0, [0.02, 0.02, 0.02, 0.10], rtol=1e-12)
    papers = np.array([c.as_array() for c in PAPER_CONSTANTS.values()])
    sets = {"0.95": "0.95 confidence", "box": "papers' Tables"}
    totals = {}
    for name, first_cell in sets.items():
        printed = next(r for r in table.rows if r[0].startswith(first_cell))
        n_all = bad_all = 0
        for k, ref in enumerate(rb.certificates):
            sw = rb.row(ref, name).sweep
            with np.errstate(invalid="ignore"):
                bad = ~sw.finite | sw.stopper_hit | (sw.min_margin < 0) | (sw.max_current > limit)
            np.testing.assert_array_equal(bad, sw.violating)
            assert printed[1 + k] == f"{bad.sum()} / {bad.size}\n{100 * (1 - bad.mean()):.1f} %"
            assert np.all(sw.start_ratio <= 1 + 1e-12)  # every start inside the certified set
            d = sw.constants - c0[:, None]
            if name == "box":
                lo, hi = papers.min(axis=0)[:, None], papers.max(axis=0)[:, None]
                assert np.all((sw.constants >= lo) & (sw.constants <= hi))
            else:  # (C - C0)' cov^-1 (C - C0) <= the chi-square quantile, 4 dof
                m = np.einsum("in,in->n", d, np.linalg.solve(cov, d))
                q = chi2.ppf(0.95, 4)
                assert np.all(m <= q * (1 + 1e-9)) and np.max(m) > chi2.ppf(0.5, 4)
                assert f"radius {math.sqrt(q):.2f} σ" in printed[0]
            n_all, bad_all = n_all + bad.size, bad_all + int(bad.sum())
        largest = max(float(np.max(rb.row(ref, name).sweep.max_current)) for ref in rb.certificates)
        assert printed[-2] == f"{largest:.2f}"
        totals[name] = (bad_all, n_all)
    assert f"0.95 confidence set {totals['0.95'][0]} of {totals['0.95'][1]} runs left F" in text
    assert f"Tables II-III box {totals['box'][0]} of {totals['box'][1]}" in text
    rows, _ = _scorecard(contents)
    assert f"{totals['0.95'][0]} of {totals['0.95'][1]} runs" in rows["The certified sets hold on"][2]
    # the bracket table and the text's first violation agree with the bisections
    radii = contents.section("Where runs first leave F")
    for c in rb.radii:
        shown = radii.row(c.reference)
        assert _numbers(shown[3])[0] == pytest.approx(c.safe_radius, rel=5e-3)  # 3 digits
        assert _numbers(shown[4])[0] == pytest.approx(c.broken_radius, rel=5e-3)
    first = min(rb.radii, key=lambda c: c.broken_radius)
    assert f"first leave F at {first.reference}, between {first.safe_radius:.3g} and" in text
