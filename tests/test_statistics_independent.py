"""Statistics and contracts checked against computations written separately from the code under
test (issue 21, item 2): standard errors against s^2 (X'X)^-1 and against their coverage over
seeds, JSON keys against SPEC 3, the validation of a platform's wiring. The tolerances say where
they come from."""

from __future__ import annotations

import numpy as np
import pytest
from scipy import stats

from maglev_oc.data.log import Log
from maglev_oc.diagnosis.result import NotSeparable
from maglev_oc.diagnosis.unexplained import Unexplained
from maglev_oc.errors import InputError
from maglev_oc.identification.verification import fit_parabola
from maglev_oc.model.parameters import DEFAULT_CONSTANTS, LumpedConstants, StageParameters
from maglev_oc.model.platform import Motor, Platform
from maglev_oc.results import Estimate


def _parabola_log(seed: int, noise: float = 20e-6, L1: float = 7.3, u1: float = -0.5, n: int = 300) -> Log:
    t = np.arange(n) * 1e-3
    x3 = -0.05 + 0.001 * t - 0.5 * L1 * u1 * t**2 + np.random.default_rng(seed).normal(0, noise, n)
    x = np.full((4, n), np.nan)
    x[0], x[2] = 0.02, x3
    return Log(t, x, np.vstack([np.full(n, u1), np.zeros(n)]))


def test_parabola_standard_error_is_s2_inverse_normal_matrix():
    # independent: numpy's unscaled covariance (X'X)^-1 of the degree-2 fit, scaled by the
    # residual variance s^2 = RSS / (n - 3); L1 = -2 c2 / u1, so se(L1) = 2 se(c2) / |u1|
    log = _parabola_log(seed=3)
    fit = fit_parabola(log, 0.02)
    t = log.t - log.t[0]
    coef, unscaled = np.polyfit(t, log.x[2], 2, cov="unscaled")
    rss = float(np.sum((np.polyval(coef, t) - log.x[2]) ** 2))
    s2 = rss / (t.size - 3)
    assert fit.L1 == pytest.approx(-2 * coef[0] / -0.5, rel=1e-9)
    assert fit.L1_stderr == pytest.approx(2 * np.sqrt(s2 * unscaled[0, 0]) / 0.5, rel=1e-9)


def test_parabola_standard_errors_cover_the_truth_over_seeds():
    # 300 runs with white noise: (L1 - 7.3) / se is Student-t with n - 3 dof, so its standard
    # deviation is 1 to within the sampling spread of a 300-sample std (1 / sqrt(600) = 0.041;
    # +-0.15 is 3.6 of those), and 95 % intervals cover 95 % (binomial sd 1.3 %: +-4 %)
    z = np.array(
        [(f.L1 - 7.3) / f.L1_stderr for f in (fit_parabola(_parabola_log(s), 0.02) for s in range(300))]
    )
    assert 0.85 < np.std(z) < 1.15
    cover = np.mean(np.abs(z) < stats.t.ppf(0.975, 297))
    assert 0.91 < cover < 0.99


def test_unexplained_and_not_separable_json_keys_follow_spec_3():
    # SPEC 3: "not_separable": [{"name", "confounded_with", "experiment"}], "unexplained":
    # [{"axis", "depends_on", "size", "description"}]; the other keys are documented details
    u = Unexplained("vertical", "gap", 0.01, 0.12, 0.05, 4.0, "a residual that depends on the gap", 0.0127)
    d = u.to_dict()
    assert {"axis", "depends_on", "size", "description"} <= set(d)
    assert (d["axis"], d["depends_on"], d["size"], d["period_m"]) == ("vertical", "gap", 0.01, 0.0127)
    assert set(d) == {
        "axis",
        "depends_on",
        "size",
        "size_unit",
        "force_rms_N",
        "holdout_gain",
        "z",
        "description",
        "period_m",
    }
    n = NotSeparable(
        "constant_vertical_force",
        ("C2", "C3"),
        "steps in the gap",
        0.02,
        "collinear",
        {"F": Estimate(9.0, 0.5, "N")},
    )
    d = n.to_dict()
    assert d["name"] == "constant_vertical_force" and d["confounded_with"] == ["C2", "C3"]
    assert d["experiment"] == "steps in the gap" and d["holdout_gain"] == 0.02
    assert d["parameters_if_it_were_separable"] == {"F": Estimate(9.0, 0.5, "N").to_dict()}


def _platform(**change) -> Platform:
    base = dict(
        coordinates=("x", "gap"),
        masses=(1.0, 1.0),
        gravity=(0.0, 9.81),
        motors=(Motor("m", (1.0, 0.0), (0.0, -1.0), (0, 1)),),
        n_inputs=2,
        params=StageParameters(),
    )
    return Platform(**{**base, **change})


@pytest.mark.parametrize(
    ("change", "message"),
    [
        (dict(motors=(Motor("m", (1.0, 0.0), (0.0, -1.0), (-1, 1)),)), r"inputs \(-1, 1\) outside 0..1"),
        (dict(motors=(Motor("m", (1.0, 0.0), (0.0, -1.0), (0, 2)),)), r"inputs \(0, 2\) outside 0..1"),
        (dict(motors=()), "at least one motor"),
        (dict(masses=(1.0, 0.0)), "masses must be positive"),
    ],
)
def test_a_platform_wired_or_weighed_wrongly_is_refused(change, message):
    _platform()  # the base is valid
    with pytest.raises(InputError, match=message):
        _platform(**change)


def test_constants_from_a_partial_dict_take_the_rest_from_the_defaults():
    c = LumpedConstants.from_dict({"C1": 15.0, "C3": 30.0}, defaults=DEFAULT_CONSTANTS)
    assert (c.C1, c.C2, c.C3, c.C4) == (15.0, DEFAULT_CONSTANTS.C2, 30.0, DEFAULT_CONSTANTS.C4)
    with pytest.raises(InputError, match="C2"):
        LumpedConstants.from_dict({"C1": 15.0, "C3": 30.0, "C4": 0.1})
