"""What the diagnosis reuses between designs and fits changes no value: designs built inside
``reusing_columns`` equal, to the bit, those built alone, and a subset fit's block sums are those of
indexing every block's Gram matrix (the fit's own way before it gathered them in one copy); the
long-run periodogram by its twiddle factors is the FFT's to rounding."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest
from numpy.testing import assert_array_equal

from maglev_oc.model.parameters import LumpedConstants
from maglev_oc.regression.data import prepare
from maglev_oc.regression.design import build_design, reusing_columns
from maglev_oc.regression.solve import fit_subset
from maglev_oc.regression.terms import constant_force, guide_friction, held_by_guides, periodic_force
from tests.test_regression import _synthetic

FIELDS = ("columns", "target", "weights", "gram", "noise", "rhs", "yy", "hold_gram", "hold_rhs", "hold_yy")


@pytest.fixture(scope="module")
def data(model):
    # currents with errors: the designs carry the errors-in-variables part too
    return prepare(
        [_synthetic(model, seconds=12.0, position_noise=3e-6, current_noise=0.01, seed=4)], bandwidth=10.0
    )


def _same(a, b) -> None:
    assert a.names == b.names
    for f in FIELDS:
        assert_array_equal(getattr(a, f), getattr(b, f), err_msg=f)


def test_designs_built_with_reused_columns_equal_those_built_alone(model, data):
    fit, hold = data.masks(0.25)
    friction = guide_friction(model.params, "horizontal", holding=lambda x, u: model.f(x, u)[3])
    periodic = periodic_force(model.params, "horizontal", 0.019)
    force = constant_force(model.params, "horizontal")
    moved = model.with_constants(
        LumpedConstants(*(1.05 * np.asarray(model.constants.as_array())), source="moved")
    )
    # the holding share depends on the references (moved with the model): a new Function, not reused;
    # the same forces held by the guides are new Functions too
    friction_moved = guide_friction(moved.params, "horizontal", holding=lambda x, u: moved.f(x, u)[3])
    held = held_by_guides(periodic, {"horizontal": 0.4})
    builds = [
        (model, (friction, periodic)),
        (moved, (friction_moved, periodic, force)),
        (moved, (force, periodic)),  # every piece seen before, in another order
        (moved, (held, dataclasses.replace(force, name="other_name"))),
        (model, ()),
    ]
    weights = build_design(data, model, fit=fit, holdout=hold).weights
    alone = [build_design(data, m, terms=t, fit=fit, holdout=hold, weights=weights) for m, t in builds]
    with reusing_columns(data) as cache:
        sizes = []
        for (m, t), expected in zip(builds, alone, strict=True):
            _same(build_design(data, m, terms=t, fit=fit, holdout=hold, weights=weights), expected)
            sizes.append(len(cache))
    # the base piece (all of C1..C4 estimated: the same Function for both models), friction, periodic;
    # the moved friction, force; nothing new; the held periodic force (the renamed force is the same
    # Function and point: reused); nothing new
    assert sizes == [3, 5, 5, 6, 6]
    # a design whose new pieces do not fit empties the cache and turns it off (a long log's library:
    # no more memory than without it); nothing changes
    with reusing_columns(data, max_bytes=cache.nbytes - 1) as small:
        for (m, t), expected in zip(builds, alone, strict=True):
            _same(build_design(data, m, terms=t, fit=fit, holdout=hold, weights=weights), expected)
            if (m, t) == builds[0]:
                assert len(small) == 3  # the first design fits
        assert len(small) == 0 and not small.active and small.nbytes == 0
    # another data set in the block is evaluated as without it
    other = prepare([_synthetic(model, seconds=12.0, seed=5)], bandwidth=10.0)
    with reusing_columns(data) as cache:
        build_design(other, model, terms=(force,))
        assert len(cache) == 0


def test_subset_fits_sum_the_blocks_as_indexing_every_block_does(model, data):
    fit, hold = data.masks(0.25)
    terms = (guide_friction(model.params, "horizontal"), periodic_force(model.params, "horizontal", 0.019))
    design = build_design(data, model, terms=terms, fit=fit, holdout=hold)
    rng = np.random.default_rng(0)
    for groups, extra in ((["base"], ()), (["base", terms[1].name], (3,)), ([terms[0].name], ())):
        idx = np.concatenate([design.indices(groups), np.asarray(extra, dtype=int)])
        for blocks in (None, rng.integers(0, design.gram.shape[0], design.gram.shape[0])):
            sel = slice(None) if blocks is None else blocks
            gram = design.gram[sel][:, idx][:, :, idx].sum(axis=0)
            rhs = design.rhs[sel][:, idx].sum(axis=0)
            noise = design.noise[sel][:, idx][:, :, idx].sum(axis=0)
            f = fit_subset(design, groups, blocks=blocks, extra=extra, compensate=True)
            assert f.compensated
            # the fit's solve (solve._solve_spd) on these sums, a column without signal held at zero
            dead = np.diag(gram) <= 1e-12 * np.max(np.diag(gram))
            g = gram - noise
            g[dead, :] = g[:, dead] = 0.0
            g[dead, dead] = 1.0
            inv = np.linalg.inv(np.linalg.cholesky(g))
            coef = np.where(dead, 0.0, inv.T @ inv @ np.where(dead, 0.0, rhs))
            assert_array_equal(f.coef, coef)


@pytest.mark.parametrize(("n", "m"), [(44854, 11), (1000, 4), (31, 4), (30, 15), (7, 4)])
def test_the_long_run_periodogram_by_its_twiddles_is_the_ffts(n, m, monkeypatch):
    # the m lowest Fourier coefficients as one product with their twiddle factors (a 60 s log's
    # 44 854 fitted samples, 2 x 41 x 547, are slow for an FFT); the FFT's values to rounding,
    # Nyquist included when m reaches it
    from maglev_oc.regression import covariance

    d = np.random.default_rng(n).standard_normal((3, n))
    direct = covariance.periodogram_long_run(d, m)
    monkeypatch.setattr(covariance, "DIRECT_DFT_SIZE", 0)
    by_fft = covariance.periodogram_long_run(d, m)
    np.testing.assert_allclose(direct, by_fft, rtol=1e-12, atol=1e-12 * np.max(np.abs(by_fft)))
