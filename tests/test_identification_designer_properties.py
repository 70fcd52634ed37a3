"""Properties of the experiment designer (``ExperimentDesigner``, ``design_experiment``, the design's
files), checked against Parseval, stand-in designers with known answers and the design's own
reference replayed:

- a prediction's nominal values are the model's constants and one newton, its RMS current
  combines the axes' RMS, and it leaves the vertical force out unless asked; the residual floor is
  white equation error of its density, and without one the noise is the differentiator's second
  derivative of white noise;
- the D-optimal design keeps the larger log det of the pairing and the best joint shape, never
  credits a singular design, hands out the reference its settings describe, and keeps its
  settings (the papers' budget at its default seed);
- the designer keeps the feasible set it is given; the continuous current limit is on the RMS of
  the current's magnitude, and violation messages give the feasible set's bounds in mm;
- a PRBS design records the settings its reference was made with; design.json names itself and
  gives peak currents under their budgets; the MATLAB file holds the design's metadata.
"""

from __future__ import annotations

import json
import math
import re
from types import SimpleNamespace

import numpy as np
import pytest
import scipy.io

import maglev_oc.identification.design as design
from maglev_oc.identification.design import (
    EFFECT,
    REFERENCE_RATE_HZ,
    CurrentBudget,
    ExperimentDesign,
    ExperimentDesigner,
    FeasibleSet,
    MultisineShape,
    Prediction,
    SampledReference,
    design_experiment,
    multisine_reference,
    papers_reference,
    prbs_reference,
    write_design,
)
from maglev_oc.identification.equation_error import EquationError
from maglev_oc.identification.experiments import TWIN_TRUTH
from maglev_oc.identification.layout import CONSTANT_NAMES
from maglev_oc.model.equilibrium import equilibrium_currents
from maglev_oc.model.stage import StageModel
from maglev_oc.regression.design import build_design
from tests._identification_cases import _prediction
from tests.test_experiment_design_properties import _reference as _flat_reference


# --- experiment design: predictions ---------------------------------------------------------------------
@pytest.fixture(scope="module")
def designer(model) -> ExperimentDesigner:
    return ExperimentDesigner(model)


@pytest.fixture(scope="module")
def short_prediction(designer):
    """(run, prediction with the constant vertical force) of a 5 s multisine on the nominal twin."""
    ref = multisine_reference(5.0)
    run = designer.simulate(ref)
    return run, designer.predict(ref, effect=True, run=run)


def test_prediction_nominal_values_are_the_models_constants_and_one_newton(model, short_prediction):
    """A prediction's relative standard errors are relative to the nominal values: C1..C4 at the
    model's constants, and the constant force, whose nominal value is 0 N, per newton (nominal
    1 N), so its relative standard error is its standard error in N. Exact: the same floats."""
    _, pred = short_prediction
    assert pred.names == (*CONSTANT_NAMES, EFFECT)
    assert list(pred.nominal[:4]) == [getattr(model.constants, c) for c in CONSTANT_NAMES]
    rel = pred.to_dict()["relative_stderr"]
    assert np.isfinite(pred.stderr[EFFECT]) and pred.stderr[EFFECT] > 0
    assert rel[EFFECT] == pred.stderr[EFFECT]
    for c in CONSTANT_NAMES:
        assert rel[c] == pytest.approx(pred.stderr[c] / abs(getattr(model.constants, c)), rel=1e-12)


def test_prediction_rms_current_combines_the_axes_rms(short_prediction):
    """The RMS of the current magnitude |i| = hypot(i_q, i_d) satisfies RMS(|i|)^2 = RMS(i_q)^2 +
    RMS(i_d)^2 (Pythagoras sample by sample), and lies below the peak magnitude. Tolerance 1e-12:
    rounding of the means."""
    run, pred = short_prediction
    assert run.success
    per_axis = float(np.nanmean(run.u[0] ** 2) + np.nanmean(run.u[1] ** 2))
    assert pred.rms_current**2 == pytest.approx(per_axis, rel=1e-12)
    assert pred.rms_current <= np.nanmax(np.hypot(run.u[0], run.u[1]))


class _StubDesigner:
    """Stands for :class:`ExperimentDesigner` in :func:`design_experiment`: every reference family
    is taken at fixed excursions (no simulation), every design predicts the same information and
    the papers' excitation less, so the design's choice is the D-optimal search's own."""

    V, H = 3e-3, 30e-3  # [m] the excursions ``fit_to_budget`` settles on

    @staticmethod
    def _prediction(log_det: float) -> Prediction:
        return Prediction(
            names=CONSTANT_NAMES,
            nominal=np.asarray(TWIN_TRUTH.as_array()),
            covariance=np.diag((0.01 * np.asarray(TWIN_TRUTH.as_array())) ** 2),
            log_det=log_det,
            peak_current=np.array([1.0, 3.0]),
            rms_current=1.0,
            gap_range=np.array([0.017, 0.023]),
            position_range=np.array([-0.03, 0.03]),
            violations=(),
        )

    def papers_budget(self, duration, *, seed=0):
        return CurrentBudget(vertical=3.0, horizontal=1.0), self._prediction(-1.0)

    def predict(self, reference, *, effect=False, budget=None, run=None):
        return self._prediction(-1.0)

    def fit_to_budget(self, make, budget, *, effect=False, iterations=4):
        return make(self.V, self.H), self._prediction(0.0)


def test_doptimal_reference_is_the_one_its_settings_describe(model):
    """The D-optimal design's settings name the multisine shape of each axis; the reference it
    hands out is the multisine of exactly those shapes (at the excursions the budget allowed). The
    grid holds one shape, not the default one, so both axes carry it. Exact: the same computation."""
    grid = (MultisineShape((0.1, 3.0), 6, 0.5),)
    design = design_experiment("doptimal", 10.0, model=model, designer=_StubDesigner(), grid=grid)

    def shape(axis):
        d = design.settings[axis]
        return MultisineShape(tuple(d["band_hz"]), d["tones"], d["tilt"])

    assert shape("vertical") == shape("horizontal") == grid[0]
    expected = multisine_reference(
        10.0,
        vertical=shape("vertical"),
        horizontal=shape("horizontal"),
        gap_amplitude=_StubDesigner.V,
        position_amplitude=_StubDesigner.H,
    )
    np.testing.assert_array_equal(design.reference.values, expected.values)


# --- experiment design ----------------------------------------------------------------------------------
def test_the_residual_floor_is_white_equation_error_of_its_density(model, twin_log):
    # white noise of one-sided density S sampled at fs has variance S fs / 2 (Parseval); under white
    # equation error of variance sigma^2 a least-squares estimate's covariance is sigma^2 H^-1,
    # H = sum over both axes of X X' (the filtered design columns on the fitted samples). The floor's
    # share of the predicted covariance is recomputed so; 1e-6 relative covers the cancellation of
    # the encoders' part in the difference
    floor = 1e-6
    extra = ExperimentDesigner(model, residual_floor=floor).covariance(twin_log) - ExperimentDesigner(
        model, residual_floor=0.0
    ).covariance(twin_log)
    prep = EquationError(twin_log, model).prepared
    design = build_design(prep, model, estimate=CONSTANT_NAMES, weights=np.ones(2))
    x = design.columns * design.fit[None, None, :]
    H = np.einsum("pan,qan->pq", x, x)
    np.testing.assert_allclose(extra, floor / prep.sample_time / 2 * np.linalg.inv(H), rtol=1e-6)


def test_the_continuous_current_limit_is_on_the_rms_of_the_current_magnitude():
    # |i| = 9 A (i_q 5.4, i_d 7.2: a 3-4-5 triangle) on 2/3 of the samples, 0 on the rest: the mean
    # is 6 A but the RMS 9 sqrt(2/3) = 7.35 A, over the amplifiers' 7 A continuous rating
    ref = _flat_reference()
    n = ref.t.size
    on = (np.arange(n) % 3) != 0
    u = np.vstack([5.4 * on, 7.2 * on])
    x = np.zeros((4, n))
    x[0] = 0.02
    run = SimpleNamespace(success=True, x=x, u=u, message="")
    flags = FeasibleSet().violations(ref, run)
    assert len(flags) == 1 and flags[0].startswith("RMS current 7.3"), flags


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


# --- violation messages name the bounds ----------------------------------------------------
_OUTSIDE = re.compile(
    r"^(simulated )?(\S+(?: set-point)?) (-?[\d.]+)\.\.(-?[\d.]+) mm outside (\S+)\.\.(\S+) mm$"
)


@pytest.mark.parametrize("seed", range(4))
def test_violation_messages_give_the_feasible_sets_bounds_in_mm(seed):
    rng = np.random.default_rng(seed)
    fs = FeasibleSet(
        gap=(rng.uniform(11e-3, 14e-3), rng.uniform(20e-3, 24e-3)),
        position=(rng.uniform(-44e-3, -30e-3), rng.uniform(30e-3, 44e-3)),
        true_gap=(rng.uniform(8.5e-3, 10e-3), rng.uniform(26e-3, 29e-3)),
        true_position=(rng.uniform(-49e-3, -45e-3), rng.uniform(45e-3, 49e-3)),
    )
    n = 50
    values = np.zeros((6, n))
    values[0] = np.linspace(fs.gap[0] - 1e-3, fs.gap[1] + 1e-3, n)
    values[3] = np.linspace(fs.position[0] - 2e-3, fs.position[1] + 2e-3, n)
    ref = SampledReference(np.arange(n) / REFERENCE_RATE_HZ, values)
    x = np.zeros((4, n))
    x[0] = np.linspace(fs.true_gap[0] - 0.5e-3, fs.true_gap[1] + 0.5e-3, n)
    x[2] = np.linspace(fs.true_position[0] - 1e-3, fs.true_position[1] + 1e-3, n)
    run = SimpleNamespace(success=True, message="", x=x, u=np.zeros((2, n)))
    out = fs.violations(ref, run)
    expected = {
        ("gap set-point", False): (values[0], fs.gap),
        ("position set-point", False): (values[3], fs.position),
        ("gap", True): (x[0], fs.true_gap),
        ("position", True): (x[2], fs.true_position),
    }
    seen = set()
    for message in out:
        m = _OUTSIDE.match(message)
        assert m, message
        key = (m.group(2), m.group(1) is not None)
        signal, (lo, hi) = expected[key]
        seen.add(key)
        assert float(m.group(3)) == pytest.approx(signal.min() * 1e3, abs=0.005 + 1e-9), message
        assert float(m.group(4)) == pytest.approx(signal.max() * 1e3, abs=0.005 + 1e-9), message
        assert float(m.group(5)) == pytest.approx(lo * 1e3, rel=1e-5), message
        assert float(m.group(6)) == pytest.approx(hi * 1e3, rel=1e-5), message
    assert seen == set(expected)


# --- the MATLAB file's metadata ----------------------------------------------------------------
def test_the_mat_file_holds_the_designs_metadata(model, tmp_path):
    n = 120
    values = np.zeros((6, n))
    values[0] = 20e-3 + 1e-3 * np.sin(np.arange(n) / 10)
    values[3] = 5e-3 * np.cos(np.arange(n) / 15)
    ref = SampledReference(np.arange(n) / REFERENCE_RATE_HZ, values, "hand_made", "a hand-made reference")
    design = ExperimentDesign(
        kind="multisine",
        reference=ref,
        targets=("C1", "C2"),
        purpose="the metadata test",
        prediction=_prediction(model),
        budget=CurrentBudget(),
        baseline=None,
        settings={"seed": 39},
    )
    paths = write_design(tmp_path / "out", design)
    mat = scipy.io.loadmat(paths["mat"], squeeze_me=True, struct_as_record=False, chars_as_strings=True)
    assert "metadata" in mat
    meta = {k: str(getattr(mat["metadata"], k)) for k in mat["metadata"]._fieldnames}
    header = {}
    for line in paths["csv"].read_text(encoding="utf-8").splitlines():
        if line.startswith("# "):
            key, _, value = line[2:].partition(": ")
            header[key.replace(" ", "_")] = value
    assert meta == header
    js = json.loads(paths["json"].read_text(encoding="utf-8"))
    assert meta["design"] == js["kind"] == "multisine"
    assert meta["targets"].split() == js["targets"] == ["C1", "C2"]
    assert meta["description"] == js["reference"]["description"] == "a hand-made reference"
    assert float(meta["sample_rate_hz"]) == js["reference"]["sample_rate_hz"] == REFERENCE_RATE_HZ


# --- the D-optimal design: a joint shape that beats the pairing -----------------------------------------
JOINT = MultisineShape((0.1, 3.0), 6, 0.5)
"""Played on both axes, the best for C1 and the best overall."""


OTHER = MultisineShape((0.2, 2.0), 8, 1.0)
"""Played on both axes, the best for C2..C4, so the pairing is (vertical OTHER, horizontal JOINT)."""


DURATION = 10.0


V, H = 3e-3, 30e-3  # [m] the excursions the stub's fit_to_budget settles on


class _ShapeDesigner:
    """Stands for :class:`ExperimentDesigner`: recognises the shape of each axis of a reference
    (its rows against each shape's multisine) and predicts per axis: C1's variance from the
    horizontal shape (JOINT's 4x smaller), C2..C4's from the vertical one (OTHER's 4x smaller). The
    log det of each design is given: JOINT alone 5, OTHER alone 4, the pairing ``paired`` (a pairing
    re-scaled to the budget can lose information to a shape that fits it better on both axes)."""

    def __init__(self, paired: float):
        self.paired = paired
        self.calls: list[tuple[MultisineShape, MultisineShape]] = []
        self.rows = {
            s: multisine_reference(DURATION, vertical=s, horizontal=s, gap_amplitude=V, position_amplitude=H)
            for s in (JOINT, OTHER)
        }

    def _shape(self, values: np.ndarray, row: int) -> MultisineShape:
        (shape,) = [s for s, ref in self.rows.items() if np.array_equal(ref.values[row], values[row])]
        return shape

    @staticmethod
    def _prediction(log_det, var_h, var_v) -> Prediction:
        nominal = np.asarray(TWIN_TRUTH.as_array())
        rel = np.array([var_h, var_v, var_v, var_v])
        return Prediction(
            CONSTANT_NAMES,
            nominal,
            np.diag(rel * nominal**2),
            log_det,
            np.array([1.0, 3.0]),
            1.0,
            np.array([0.017, 0.023]),
            np.array([-0.03, 0.03]),
            (),
        )

    def papers_budget(self, duration, *, seed=0):
        return CurrentBudget(vertical=3.0, horizontal=1.0), self._prediction(-10.0, 1.0, 1.0)

    def predict(self, reference, *, effect=False, budget=None, run=None):
        return self._prediction(-10.0, 1.0, 1.0)  # the papers' excitation: far below every shape

    def fit_to_budget(self, make, budget, *, effect=False, iterations=4):
        ref = make(V, H)
        vertical, horizontal = self._shape(ref.values, 0), self._shape(ref.values, 3)
        self.calls.append((vertical, horizontal))
        var_h = 1e-4 if horizontal == JOINT else 4e-4
        var_v = 1e-4 if vertical == OTHER else 4e-4
        if vertical == horizontal:
            log_det = 5.0 if vertical == JOINT else 4.0
        else:
            log_det = self.paired
        return ref, self._prediction(log_det, var_h, var_v)


@pytest.mark.parametrize(
    ("paired", "vertical", "horizontal"),
    [(1.0, JOINT, JOINT), (9.0, OTHER, JOINT)],
    ids=["joint_shape_wins", "pairing_wins"],
)
def test_doptimal_keeps_the_larger_log_det_of_the_pairing_and_the_best_joint_shape(
    model, paired, vertical, horizontal
):
    """The pairing (vertical OTHER, horizontal JOINT) is tried; if its log det (1) is below JOINT's
    on both axes (5), the design is JOINT on both axes: settings, reference and prediction; if it
    is above (9), the pairing stays. Exact: the stub's numbers and the same multisine computation."""
    designer = _ShapeDesigner(paired)
    design = design_experiment("doptimal", DURATION, model=model, designer=designer, grid=(JOINT, OTHER))
    assert (OTHER, JOINT) in designer.calls  # the pairing was tried
    assert design.settings["vertical"] == vertical.to_dict()
    assert design.settings["horizontal"] == horizontal.to_dict()
    expected = multisine_reference(
        DURATION, vertical=vertical, horizontal=horizontal, gap_amplitude=V, position_amplitude=H
    )
    np.testing.assert_array_equal(design.reference.values, expected.values)
    assert design.prediction.log_det == max(paired, 5.0)
    # the candidates are JSON (the shape objects used in the search are not left in them)
    json.dumps(design.to_dict())
    assert [c["log_det"] for c in design.candidates[:2]] == [5.0, 4.0]


# --- papers_budget's default -----------------------------------------------------------------------
def test_the_papers_budget_defaults_to_the_papers_excitation_at_its_default_seed():
    seen = []

    def predict(ref):
        seen.append(ref)
        return SimpleNamespace(success=True, message="", peak_current=np.array([1.25, 2.5]))

    duration = 8.0
    stand_in = SimpleNamespace(predict=predict)  # the designer's twin replaced: only the reference matters
    budget, _ = design.ExperimentDesigner.papers_budget(stand_in, duration)
    assert budget == CurrentBudget(vertical=2.5, horizontal=1.25)  # peaks are (i_q, i_d)
    default = papers_reference(duration)
    assert not np.array_equal(papers_reference(duration, seed=1).values, default.values)  # seeds differ
    assert np.array_equal(seen[0].t, default.t) and np.array_equal(seen[0].values, default.values)


# --- D-optimal: a singular covariance is no information ----------------------------------------------
def test_the_doptimal_search_never_credits_a_singular_design_with_information(model, monkeypatch):
    nominal = np.array(model.constants.as_array())
    good, degenerate = MultisineShape(tilt=0.0), MultisineShape(tilt=1.0)

    def relative_cov(c1_rel_var: float, vertical_rel: np.ndarray) -> np.ndarray:
        rel = np.zeros((4, 4))
        rel[0, 0] = c1_rel_var
        rel[1:, 1:] = vertical_rel
        return rel * np.outer(nominal, nominal)

    # good: 1 % on every constant; degenerate: C2..C4 perfectly correlated (rank 1 of 3: two
    # directions without a finite figure), C1 worse than good's so the horizontal choice is clear
    covs = {
        good: relative_cov(1e-4, 1e-4 * np.eye(3)),
        degenerate: relative_cov(4e-4, 1e-4 * np.ones((3, 3))),
    }

    def log_det(cov):  # Prediction.log_det's convention (ExperimentDesigner.predict)
        sign, ld = np.linalg.slogdet(cov / np.outer(nominal, nominal))
        return -float(ld) if sign > 0 else -math.inf

    def prediction(vertical, horizontal):
        cov = covs[horizontal].copy()
        cov[1:, 1:] = covs[vertical][1:, 1:]
        return SimpleNamespace(nominal=nominal, covariance=cov, log_det=log_det(cov))

    class Designer:
        def fit_to_budget(self, make, budget, **kwargs):
            vertical, horizontal = make(1e-3, 1e-3)
            return (vertical, horizontal), prediction(vertical, horizontal)

    monkeypatch.setattr(
        design,
        "multisine_reference",
        lambda duration, *, vertical, horizontal, gap_amplitude, position_amplitude: (vertical, horizontal),
    )
    ref, pred, rows, chosen = design._doptimal(Designer(), 40.0, CurrentBudget(), [degenerate, good])
    by_tilt = {r["shape"]["tilt"]: r for r in rows}
    assert by_tilt[1.0]["log_det"] == -math.inf
    assert by_tilt[1.0]["log_det_C2_C4"] == -math.inf  # no information, as the joint criterion says
    assert math.isfinite(by_tilt[0.0]["log_det_C2_C4"])
    assert chosen == {"vertical": good.to_dict(), "horizontal": good.to_dict()}
    assert ref == (good, good) and math.isfinite(pred.log_det)


def test_a_prediction_leaves_the_vertical_force_out_unless_asked(model):
    """A 5 s multisine on the nominal twin: by default the prediction names C1..C4 with a 4 x 4
    covariance; asked for the force, 5 names and a 5 x 5 covariance whose constants' block is
    larger on C2's diagonal (the force and C2 both set the vertical force's mean; 1 %: far above the
    rounding of two solves of the same normal equations, far below the effect measured, x1.3 or
    more)."""
    designer = ExperimentDesigner(model)
    ref = multisine_reference(5.0)
    run = designer.simulate(ref)
    plain = designer.predict(ref, run=run)
    both = designer.predict(ref, effect=True, run=run)
    assert plain.names == CONSTANT_NAMES and plain.covariance.shape == (4, 4)
    assert both.names == (*CONSTANT_NAMES, EFFECT) and both.covariance.shape == (5, 5)
    c2 = CONSTANT_NAMES.index("C2")
    assert both.covariance[c2, c2] > 2.0 * plain.covariance[c2, c2]
    assert np.all(np.isfinite(plain.covariance))


# --- the design when the papers' excitation wins -----------------------------------------------------
class _PapersWin(_ShapeDesigner):
    """The shape designer of the seed-41 tests whose papers' excitation predicts more than every
    shape (log det 50 against at most 9)."""

    def predict(self, reference, *, effect=False, budget=None, run=None):
        return self._prediction(50.0, 1e-5, 1e-5)


@pytest.mark.parametrize("designer", [_PapersWin(1.0), _ShapeDesigner(1.0)], ids=["papers_win", "joint_wins"])
def test_a_design_keeps_its_settings_and_its_rows_are_plain_data(model, designer):
    design = design_experiment("doptimal", DURATION, model=model, designer=designer, grid=(JOINT, OTHER))
    assert design.settings["duration_s"] == DURATION and design.settings["seed"] == 0
    if isinstance(designer, _PapersWin):
        assert design.settings["vertical"] == design.settings["horizontal"] == "papers' sum of sines"
    else:
        assert design.settings["vertical"] == JOINT.to_dict()
    for row in design.candidates:
        assert not [k for k in row if k.startswith("_")], row
    json.dumps(design.to_dict())  # every field is plain data


def test_the_designer_keeps_the_feasible_set_it_is_given(model):
    """Seed 58: ``ExperimentDesigner(feasible=...)`` designs inside the set it is given (a user's
    stoppers or current limit), not the default one."""
    from maglev_oc.identification.design import ExperimentDesigner
    from maglev_oc.region.feasibility import FeasibleSet

    limited = FeasibleSet(model, current_limit=4.0)
    assert ExperimentDesigner(model, feasible=limited).feasible is limited
    assert ExperimentDesigner(model).feasible is not limited


def test_the_designers_noise_covariance_is_the_differentiators_second_derivative_of_white_noise():
    """ExperimentDesigner.covariance with no residual floor: white encoder noise of variance s^2
    reaches the equation error through the Savitzky-Golay second derivative, so the covariance is
    s^2 H^-1 (sum over axes of G G') H^-1, G the columns filtered by that derivative. Its taps are
    computed here from their definition (the least-squares polynomial of the filter's order over
    its window, twice its t^2 coefficient at the centre), not by scipy; 1e-9 relative (rounding).
    A residual floor adds its own white part on top."""
    from maglev_oc.identification import design as D
    from maglev_oc.identification.equation_error import EquationError
    from maglev_oc.identification.experiments import LOG_RATE_HZ
    from maglev_oc.regression.base import CONSTANT_NAMES
    from maglev_oc.regression.design import build_design
    from maglev_oc.sim.recording import result_to_log

    model = StageModel()
    designer = D.ExperimentDesigner(model, residual_floor=0.0)
    log = result_to_log(designer.simulate(D.papers_reference(10.0)), rate_hz=LOG_RATE_HZ)
    cov = designer.covariance(log)

    prep = EquationError(log, model, estimate=CONSTANT_NAMES).prepared
    design = build_design(prep, model, estimate=CONSTANT_NAMES, weights=np.ones(2))
    x = design.columns * design.fit[None, None, :]  # the fitted samples' columns
    sg = prep.differentiator
    half = sg.acceleration_window // 2
    tau = np.arange(-half, half + 1) * sg.sample_time
    vandermonde = tau[:, None] ** np.arange(sg.polyorder + 1)[None, :]
    taps = 2.0 * np.linalg.pinv(vandermonde)[2]  # y''(centre) = sum_k taps_k y(centre + tau_k)
    assert taps @ (0.5 * tau**2) == pytest.approx(1.0, rel=1e-9)  # the second derivative of t^2 / 2
    H = sum(x[:, a, :] @ x[:, a, :].T for a in range(2))
    G = [np.array([np.convolve(row, taps, mode="full") for row in x[:, a, :]]) for a in range(2)]
    M = designer.noise_variance * sum(g @ g.T for g in G)
    Hi = np.linalg.inv(H)
    np.testing.assert_allclose(cov, Hi @ M @ Hi, rtol=1e-9, atol=0.0)
    # a residual floor (a white equation error of variance floor * fs / 2) adds floor fs / 2 H^-1
    floor = 1e-4
    with_floor = D.ExperimentDesigner(model, residual_floor=floor).covariance(log)
    added = floor / (2 * sg.sample_time) * Hi
    np.testing.assert_allclose(with_floor - cov, added, rtol=1e-6, atol=1e-9 * np.max(np.abs(added)))
