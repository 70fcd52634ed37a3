"""The thrust side (``maglev_oc.diagnosis.thrust_current``): effects of the thrust current judged by
how well they predict the logged thrust current.

* ``restated`` with a design's own columns, target and weights gives back the block sums and
  held-out normal equations ``build_design`` accumulated (another code path, to 1e-9), without the
  errors-in-variables correction;
* the restated residual is the acceleration residual in amperes: the model's Jacobian in the
  currents, by central differences of its right-hand side (not CasADi's derivative), times the
  base fit's restated residual gives back its acceleration residual (to 1e-4 of its RMS, the
  differences' truncation);
* the base model restated in amperes predicts the felt thrust current (the columns are evaluated at
  the currents that make the model produce the measured accelerations), up to the ratio of the
  fitted C1 to the model's, within 5 % of how far the logged one is from it;
* the side is used where the logged thrust current's error floor is most of the horizontal
  residual no column explains: on a clean log of the generator's noisy rig (1.03-1.40 times it on
  five seeds, bench/README *Judged on the thrust current*), not on its default rig (0.23-0.25);
* slow: on the noisy rig a 5 % thrust ripple (the generator's large one) that the accelerations do
  not show is claimed from the thrust current and sized within 30 % (the issue's size criterion),
  while the clean log of the same seed claims nothing and gives the ripple a detection limit below
  5 % (the limit is the size the log would have shown).
"""

from __future__ import annotations

import numpy as np
import pytest

from maglev_oc.data.logs import read_log
from maglev_oc.diagnosis.candidate import LibraryContext
from maglev_oc.diagnosis.currents import ripple_candidate
from maglev_oc.diagnosis.selection import THRUST_SIDE
from maglev_oc.diagnosis.thrust_current import ERROR_SHARE, THRUST, error_share, felt_currents, thrust_side
from maglev_oc.regression.data import prepare
from maglev_oc.regression.design import build_design, restated
from maglev_oc.regression.solve import fit_subset
from tests.diagnosis_support import diagnose_path
from tests.independent import write_log
from tests.independent.effects import ThrustRipple
from tests.independent.simulate import Rig, Scenario, simulate

NOISY = Rig(observer_bandwidth=2800.0)
"""The generator's rig with currents as noisy as ``../shared/logs/independent_clean.csv``'s
(``bench/diagnose_rigs.py``'s ``obs2800``)."""
SEED = 204
"""A seed whose 5 % ripple the thrust side showed (z 3.7) and the accelerations did not (bench/README,
*Judged on the thrust current*)."""


def _design(path, model):
    data = prepare([read_log(path)], bandwidth=10.0)
    fit, hold = data.masks(0.25)
    ripple = ripple_candidate(LibraryContext(model, data))
    return build_design(data, model, terms=[ripple.term], fit=fit, holdout=hold)


@pytest.fixture(scope="module")
def noisy_clean(tmp_path_factory):
    """A clean 60 s log of the noisy rig: its path."""
    run = simulate(Scenario(name="clean", seed=SEED, effects=(), rig=NOISY))
    path, _ = write_log(run, tmp_path_factory.mktemp("thrust_side"), stem="clean")
    return path


@pytest.fixture(scope="module")
def noisy_design(noisy_clean, model):
    return _design(noisy_clean, model)


def _close(a, b, rtol=1e-9):
    scale = max(float(np.max(np.abs(b))), 1e-300)
    return float(np.max(np.abs(np.asarray(a) - np.asarray(b)))) <= rtol * scale


def test_restated_with_its_own_columns_is_the_design(noisy_design):
    d = noisy_design
    again = restated(d, d.columns, d.target, d.weights)
    for name in ("gram", "rhs", "yy", "hold_gram", "hold_rhs", "hold_yy"):
        assert _close(getattr(again, name), getattr(d, name)), name
    assert np.array_equal(again.block_of, d.block_of)
    assert not np.any(again.noise)  # no errors-in-variables correction in other units


def test_the_restated_residual_is_the_acceleration_residual_in_amperes(noisy_design, model):
    side = thrust_side(noisy_design, model)
    assert side is not None
    base = fit_subset(noisy_design, ["base"], covariance=False)
    residual = noisy_design.target - np.tensordot(base.coef, noisy_design.columns[base.index], axes=1)
    in_amperes = side.design.target - np.tensordot(base.coef, side.design.columns[base.index], axes=1)
    # the Jacobian by central differences at the felt currents, on the held-out samples
    felt = felt_currents(noisy_design.prepared, model)
    hold = np.flatnonzero(noisy_design.holdout)[::50]
    f = model.f.map(hold.size)
    x, u = felt.x[:, hold], felt.u[:, hold]
    J = np.empty((2, 2, hold.size))  # (axis, current, sample)
    for i in range(2):
        h = np.zeros((2, 1))
        h[i] = 1e-4
        plus, minus = (np.asarray(f(x, u + s * h))[[1, 3]] for s in (1.0, -1.0))
        J[:, i] = (plus - minus) / 2e-4
    currents = in_amperes[[1, 0]][:, hold]  # rows (vertical: i_d, horizontal: i_q) -> (i_q, i_d)
    back = np.einsum("ain,in->an", J, currents)
    for a in np.flatnonzero(noisy_design.moving):
        rms = float(np.sqrt(np.mean(residual[a, hold] ** 2)))
        assert float(np.max(np.abs(back[a] - residual[a, hold]))) <= 1e-4 * rms, a


def test_the_model_restated_in_amperes_needs_the_felt_thrust_current_not_the_logged_one(noisy_design, model):
    # the base fit's thrust current for the measured motion: its columns at the felt currents, so
    # (the thrust linear in i_q) the filtered felt thrust current itself, to the filter's smoothing
    # of J; the logged current differs from it by its logging error, which the columns must not carry
    side = thrust_side(noisy_design, model)
    base = fit_subset(noisy_design, ["base"], covariance=False)
    predicted = np.tensordot(base.coef, side.design.columns[base.index], axes=1)[THRUST]
    prep = noisy_design.prepared
    felt, logged = (prep.filter(u[0]) for u in (felt_currents(prep, model).u, prep.u))
    hold = noisy_design.holdout
    error = float(np.sqrt(np.mean((logged[hold] - felt[hold]) ** 2)))
    # up to the ratio of the fitted C1 to the model's, which the felt currents were inverted with
    scale = float(predicted[hold] @ felt[hold] / (felt[hold] @ felt[hold]))
    assert abs(scale - 1.0) < 0.05  # the constants a few per cent off the papers'
    assert float(np.sqrt(np.mean((predicted[hold] - scale * felt[hold]) ** 2))) <= 0.05 * error


def test_the_side_is_used_where_the_logged_thrust_current_is_mostly_its_error(noisy_design, generated, model):
    noisy = error_share(noisy_design, model)
    default = error_share(_design(generated("clean", "clean_01")[0], model), model)
    # the floor over the residual no column explains: above 1 where the logged currents' columns
    # absorb part of their own error (1.03-1.40 on five noisy clean logs, bench/README)
    assert ERROR_SHARE < noisy < 2.0
    assert 0.0 < default < ERROR_SHARE
    assert thrust_side(_design(generated("clean", "clean_01")[0], model), model) is None


@pytest.mark.slow
def test_a_ripple_the_accelerations_cannot_show_is_seen_on_the_thrust_current(noisy_clean, tmp_path):
    run = simulate(
        Scenario(name="ripple", seed=SEED, effects=(ThrustRipple(ratio=0.05, ratio2=0.0),), rig=NOISY)
    )
    path, _ = write_log(run, tmp_path, stem="ripple")
    found = diagnose_path(path)
    assert [e.name for e in found.effects] == ["thrust_ripple"]
    ripple = found.effects[0]
    assert ripple.judged_on == THRUST_SIDE
    step = found.selection.steps[0].judgements["thrust_ripple"]
    # on the accelerations alone it would not have passed: the side is what showed it
    assert step.side == THRUST_SIDE
    assert abs(ripple.parameters["amplitude"].value - 0.05) <= 0.3 * 0.05
    clean = diagnose_path(noisy_clean, limits=True)
    assert clean.effects == []
    # shown on neither side, a candidate of the thrust current keeps the accelerations' numbers and
    # says what the thrust current showed
    for name in ("thrust_ripple", "current_saturation", "magnet_field_gap_dependence"):
        j = clean.selection.last[name]
        assert j.side == "" and "predicting the logged thrust current" in j.reason, (name, j.reason)
    limits = {d.name: d for d in clean.detection_limits}
    assert limits["thrust_ripple"].value < 0.05
