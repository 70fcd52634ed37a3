"""The controller report (analyses/controllers.py): it builds with no near-empty page, speaks in
words, and every scorecard row prints what the simulations give. Each row's numbers are
recomputed here from the runs' arrays (time, readings, references, commands) with this file's own
settling, overshoot and tracking-error code, not the library's metrics, and compared with the
printed strings to their printed precision. The papers' column is checked against 002 Sec. 7 and
001 Sec. VI as SPEC 4 quotes them.

The report is the one ``maglev-oc report`` writes, with the NMPC and the calibrated twin, built once
per session (tests/report_support.py) and shared with tests/test_calibration.py, which checks the
calibration and the report's calibrated-twin rows. (Checking a quicker variant without them here
cost 14 s of CPU more per run and left the user's report's own scorecard unchecked.)
"""

from __future__ import annotations

import math
import re

import numpy as np
import pytest

from maglev_oc.model.hardware import PEAK_CURRENT_LIMIT

BAND = 1e-4  # [m] the papers' 0.1 mm
ENCODER = 1e-5  # [m] 10 um
HOLD = 0.2  # [s] a band entered later than this before the next change does not count (sim.metrics)
SECONDS = 0.0051  # settling times are printed to 0.01 s
PERCENT = 0.51  # overshoots are printed to 1 %


@pytest.fixture(scope="module")
def whole(shared_controllers_report):
    """(study, contents) of the report ``maglev-oc report`` writes, with the NMPC and the calibrated
    twin (tests/report_support.py; tests/test_calibration.py checks its calibration)."""
    return shared_controllers_report[1:]


# --- this file's own scoring of a run ---------------------------------------------------------------------
def _errors(run) -> np.ndarray:
    """Reading minus reference, (2, n): vertical, horizontal."""
    return np.vstack([run.y[0] - run.reference[0], run.y[1] - run.reference[3]])


def _segments(run):
    """(start index, end index, signed step (2,)) of each set-point change of the run."""
    changes = [0, *(np.nonzero(np.any(np.diff(run.reference[[0, 3]], axis=1) != 0, axis=0))[0] + 1)]
    start = np.array([run.x[0, 0], run.x[2, 0]])
    out = []
    for k, i in enumerate(changes):
        j = changes[k + 1] if k + 1 < len(changes) else run.t.size
        target = run.reference[[0, 3], i]
        out.append((i, j, target - start))
        start = target
    return out


_SETTLED: dict = {}


def _settling(run, axis: int, band: float) -> list[float]:
    """Per change: time until |error| stays within ``band`` to the next change (NaN if never, or if
    it enters less than HOLD before it); a reading on the band's edge by round-off is inside."""
    key = (id(run), axis, band)
    if key not in _SETTLED:
        _SETTLED[key] = (run, _settling_of(run, axis, band))  # the run kept: its id stays its own
    return _SETTLED[key][1]


def _settling_of(run, axis: int, band: float) -> list[float]:
    e = _errors(run)[axis]
    out = []
    for i, j, _ in _segments(run):
        settled = math.nan
        for k in range(j - 1, i - 1, -1):  # walk back to the last reading outside the band
            if abs(e[k]) > band * (1 + 1e-9):
                if k + 1 < j and run.t[j - 1] - run.t[k + 1] >= HOLD:
                    settled = run.t[k + 1] - run.t[i]
                break
        else:
            settled = 0.0
        out.append(settled)
    return out


def _overshoot(run, axis: int) -> list[float]:
    """Per change: the largest excursion beyond the new set-point in % of the step (NaN under 0.5 mm)."""
    e = _errors(run)[axis]
    out = []
    for i, j, step in _segments(run):
        if abs(step[axis]) < 5e-4:
            out.append(math.nan)
        else:
            out.append(max(float(np.max(np.sign(step[axis]) * e[i:j])), 0.0) / abs(step[axis]) * 100)
    return out


def _tracking(run, axis: int, start: float = 8.0) -> tuple[float, float]:
    """Mean and peak |error| from ``start`` [s] on (the ellipse's scoring window)."""
    e = np.abs(_errors(run)[axis, run.t >= start])
    return float(np.mean(e)), float(np.max(e))


def _peak(run) -> float:
    return float(np.nanmax(np.hypot(run.u[0], run.u[1])))


def _numbers(text: str) -> list[float]:
    return [float(v) for v in re.findall(r"-?\d+(?:\.\d+)?", text)]


def _row(contents, first: str) -> tuple[str, ...]:
    table = contents.section("Scorecard")
    found = [r for r in table.rows if r[0].startswith(first)]
    assert len(found) == 1, first
    return found[0]


# --- the layout -------------------------------------------------------------------------------------------
def test_the_report_is_whole_with_no_near_empty_page(whole):
    _, contents = whole
    assert contents.path.read_bytes()[:5] == b"%PDF-"
    pages = len(re.findall(rb"/Type\s*/Page[^s]", contents.path.read_bytes()))
    assert pages == contents.n_pages == len(contents.pages) >= 10
    assert contents.sparse_pages() == []
    assert contents.headings[0].startswith("Scorecard")
    assert contents.pages[-1].heading.startswith("Appendix")


def test_the_report_speaks_in_words(whole):
    _, contents = whole
    text = contents.text()
    for internal in ("mapaccum", "TwinEffects", "rig()", "table3", "eps0", "setpoint_steps", "RunMetrics"):
        assert internal not in text, internal
    snake = set(re.findall(r"\b[a-z][a-z0-9]+_[a-z0-9_]+\b", text)) - {"maglev_oc"}
    assert not snake, snake
    # the R < 0 count is named for what it is, apart from the amplifier's limit
    table = contents.section("Currents")
    assert "R < 0\n[samples]" in table.columns and "amplifier\nclipped [ms]" in table.columns


# --- the scorecard, row by row ----------------------------------------------------------------------------
def test_scorecard_papers_column_is_spec_4(whole):
    _, contents = whole
    expected = {
        "Vertical error below 0.1 mm": "< 1.3 s",
        "Horizontal error below 0.1 mm": "four < 1.2 s,\nthe fifth 2.38 s",
        "Vertical overshoot at t = 5 s": "114 %",
        "Horizontal overshoot": "43 %",
        "Retuned K_v": "40 %, x3\n(still < 3 s)",
        "Large step": "unstable",
        "Ellipse: mean (peak) |error|,\nhorizontal": "0.11 (0.4) mm",
        "Ellipse: mean (peak) |error|,\nvertical": "0.24 (0.8) mm",
        "PID on the ellipse": "0.19 / 0.9 mm",
        "Amplifiers": "≤ 9 A",
    }
    for first, paper in expected.items():
        assert _row(contents, first)[1] == paper, first


@pytest.mark.parametrize(
    ("first", "axis", "limit"), [("Vertical error below", 0, 1.3), ("Horizontal error below", 1, 1.2)]
)
def test_scorecard_settling_is_every_step(whole, first, axis, limit):
    study, contents = whole
    _, _, ours, verdict = _row(contents, first)
    run = study.result("FL regulator", "setpoint_steps", "rig")
    times = _settling(run, axis, BAND)
    assert _numbers(ours) == pytest.approx(times, abs=SECONDS)
    under = sum(t < limit for t in times)
    if axis == 0:
        assert verdict == ("reproduced" if under == 5 else f"differs: {5 - under} of 5 slower")
    else:
        assert verdict.startswith(
            "reproduced" if under >= 4 and max(times) <= 2.38 else f"differs: {under} of 5"
        )
        if not verdict.startswith("reproduced"):
            design = _settling(study.result("FL regulator", "setpoint_steps", "ideal"), 1, BAND)
            assert _numbers(verdict.split("\n")[1]) == pytest.approx([min(design), max(design)], abs=SECONDS)


def test_scorecard_encoder_resolution(whole):
    study, contents = whole
    _, _, ours, verdict = _row(contents, "Error within the encoders'")
    run = study.result("FL regulator", "setpoint_steps", "rig")
    h = _settling(run, 1, ENCODER)
    v = _settling(run, 0, ENCODER)
    printed = _numbers(ours)
    assert printed[:2] == pytest.approx([np.nanmin(h), np.nanmax(h)], abs=SECONDS)
    assert printed[2] == sum(math.isfinite(x) for x in v)
    # what is left of the vertical error in the last second before each change, worst step
    e = np.abs(_errors(run)[0])
    left = max(
        float(np.max(e[(run.t >= run.t[j - 1] - 1.0 + 1e-9) & (run.t <= run.t[j - 1])]))
        for _, j, _ in _segments(run)
    )
    assert printed[-1] == pytest.approx(left * 1e6, abs=0.5)
    if not all(math.isfinite(x) for x in v):
        ideal = _settling(study.result("FL regulator", "setpoint_steps", "ideal"), 0, ENCODER)
        assert _numbers(verdict)[-1] == pytest.approx(max(ideal), abs=SECONDS)


def test_scorecard_overshoots(whole):
    study, contents = whole
    run = study.result("FL regulator", "setpoint_steps", "rig")
    v, h = _overshoot(run, 0), _overshoot(run, 1)
    _, _, ours, verdict = _row(contents, "Vertical overshoot at t = 5 s")
    at5, largest = _numbers(ours.replace("five", ""))
    assert at5 == pytest.approx(v[1], abs=PERCENT)  # the second change is the one at t = 5 s
    assert largest == pytest.approx(np.nanmax(v), abs=PERCENT)
    assert verdict.startswith("reproduced" if abs(v[1] - 114) <= 15 else "differs")
    if verdict.startswith("differs"):
        design = _overshoot(study.result("FL regulator", "setpoint_steps", "ideal"), 0)[1]
        assert _numbers(verdict)[0] == pytest.approx(design, abs=PERCENT)
    _, _, ours, verdict = _row(contents, "Horizontal overshoot")
    assert _numbers(ours)[0] == pytest.approx(np.nanmax(h), abs=PERCENT)
    assert verdict == ("reproduced" if abs(np.nanmax(h) - 43) <= 15 else verdict)


def test_scorecard_retuned_gains(whole):
    study, contents = whole
    _, _, ours, verdict = _row(contents, "Retuned K_v")
    printed = study.result("FL regulator", "setpoint_steps", "rig")
    retuned = study.result("FL regulator, retuned K_v", "setpoint_steps", "rig")
    over = _overshoot(retuned, 0)[1]
    ratio = _settling(retuned, 0, BAND)[1] / _settling(printed, 0, BAND)[1]
    o, r, t = _numbers(ours)
    assert o == pytest.approx(over, abs=PERCENT)
    assert r == pytest.approx(ratio, abs=0.051)
    assert t == pytest.approx(_settling(retuned, 0, BAND)[1], abs=SECONDS)
    assert verdict == ("reproduced" if abs(over - 40) <= 15 and abs(ratio - 3) <= 0.5 else "differs")


def test_scorecard_linear_against_nonlinear(whole):
    study, contents = whole
    _, _, ours, verdict = _row(contents, "Small step")
    names = ("FL regulator", "linear regulator", "linear regulator (no feedforward)")
    runs = [study.result(n, "small_step", "rig") for n in names]
    assert _numbers(ours) == pytest.approx([_overshoot(r, 0)[0] for r in runs], abs=PERCENT)
    assert verdict.startswith("both settle") == all(r.success for r in runs)

    _, _, ours, verdict = _row(contents, "Large step")
    large = study.result("linear regulator (no feedforward)", "large_step", "rig")
    assert ours.startswith("without feedforward: " + ("survives" if large.success else "hits the stopper"))
    with_ff = study.result("linear regulator", "large_step", "rig")
    assert ours.endswith("with feedforward: " + ("survives" if with_ff.success else "hits the stopper"))
    assert _numbers(ours)[0] == pytest.approx(np.min(large.x[0]) * 1e3, abs=0.051)
    sweep = study.sweeps["rig"]
    fails = sweep.target_gaps[~sweep.success[sweep.controllers.index("linear regulator (no feedforward)")]]
    assert _numbers(ours)[1] == pytest.approx(fails.max() * 1e3)
    # the sweep's outcome at the papers' 18 mm is the large step's (same start, target, twin)
    k = int(np.argmin(np.abs(sweep.target_gaps - 0.018)))
    assert sweep.success[sweep.controllers.index("linear regulator (no feedforward)"), k] == large.success
    fl = study.result("FL regulator", "large_step", "rig")
    assert verdict.startswith("reproduced" if (not large.success and fl.success) else "differs")


@pytest.mark.parametrize(
    ("first", "axis", "paper"),
    [
        ("Ellipse: mean (peak) |error|,\nhorizontal", 1, 0.11),
        ("Ellipse: mean (peak) |error|,\nvertical", 0, 0.24),
    ],
)
def test_scorecard_ellipse(whole, first, axis, paper):
    study, contents = whole
    _, _, ours, verdict = _row(contents, first)
    mean, peak = _tracking(study.result("FL regulator", "sinusoid", "rig"), axis)
    ideal, _ = _tracking(study.result("FL regulator", "sinusoid", "ideal"), axis)
    m, p, i = _numbers(ours)
    assert m == pytest.approx(mean * 1e3, abs=5e-4)
    assert p == pytest.approx(peak * 1e3, abs=5e-3)
    assert i == pytest.approx(ideal * 1e6, rel=0.05)  # printed to two significant digits
    within = 1 / 1.5 <= mean * 1e3 / paper <= 1.5
    assert verdict.startswith("reproduced" if within else "differs")


def test_scorecard_pid_on_the_ellipse(whole):
    study, contents = whole
    _, _, ours, verdict = _row(contents, "PID on the ellipse")
    run = study.result("PID", "sinusoid", "rig")
    h, v = _tracking(run, 1)[0], _tracking(run, 0)[0]
    assert _numbers(ours) == pytest.approx([h * 1e3, v * 1e3], abs=5e-4)
    # 001 Sec. VI-B: 0.19 mm horizontal, about 0.9 mm vertical
    ok = 1 / 1.5 <= h * 1e3 / 0.19 <= 1.5 and 1 / 1.5 <= v * 1e3 / 0.9 <= 1.5
    assert verdict == ("reproduced" if ok else "differs")


def test_scorecard_flags_commands_above_the_amplifier_rating(whole):
    study, contents = whole
    _, _, ours, verdict = _row(contents, "Amplifiers")
    cmp = study.comparison
    peaks = {n: max(_peak(cmp.results[(n, sc, "rig")]) for sc in cmp.scenarios) for n in cmp.controllers}
    over = {n: p for n, p in peaks.items() if p > PEAK_CURRENT_LIMIT}
    assert over, "the PID and LQR command more than 9 A on the set-point steps"
    printed = dict(
        re.findall(r"([A-Za-z][A-Za-z ()]*?) (\d+\.\d) A", ours.replace("commanded: ", "").replace("\n", " "))
    )
    assert len(printed) == len(over)
    for value in over.values():
        assert any(abs(float(v) - value) <= 0.051 for v in printed.values())
    assert verdict.startswith(f"flagged: {len(over)} of {len(peaks)}")


def test_step_table_is_every_step_and_controller(whole):
    study, contents = whole
    cmp = study.comparison
    for twin, heading in (
        ("rig", "Set-point steps, step by step: rig"),
        ("ideal", "Set-point steps, step by step: ideal"),
    ):
        table = contents.section(heading)
        assert len(table.rows) == 5 * len(cmp.controllers)
        for k, row in enumerate(table.rows):
            run = cmp.results[(row[1], "setpoint_steps", twin)]
            step = k // len(cmp.controllers)
            expected = [
                _settling(run, 0, BAND)[step],
                _settling(run, 1, BAND)[step],
                _settling(run, 0, ENCODER)[step],
                _settling(run, 1, ENCODER)[step],
            ]
            for cell, value in zip(row[2:6], expected, strict=True):
                assert (cell == "—") == (not math.isfinite(value)), (row, cell, value)
                if cell != "—":
                    assert float(cell) == pytest.approx(value, abs=SECONDS), row
            for cell, value in zip(
                row[6:8], (_overshoot(run, 0)[step], _overshoot(run, 1)[step]), strict=True
            ):
                assert float(cell) == pytest.approx(value, abs=PERCENT), row


def test_amplifier_table_names_the_commands_over_9_a(whole):
    study, contents = whole
    table = contents.section("Currents")
    name = ""
    for row in table.rows:
        name = row[0] or name  # a controller's name is on its first row only
        twin = "ideal" if row[1] == "ideal twin" else "rig"
        runs = [study.result(name, sc, twin) for sc in study.comparison.scenarios]
        assert _numbers(" ".join(row[2:6])) == pytest.approx([_peak(r) for r in runs], abs=0.051), row
        above = sum(int(np.sum(np.hypot(r.u[0], r.u[1]) > PEAK_CURRENT_LIMIT)) for r in runs)
        assert float(row[6]) == pytest.approx(above * runs[0].sample_time * 1e3, abs=0.051), row
