"""The estimation package against independent computations (issue 21; survivors of the mutation run
of seed 53): the extended observer's innovation integral against a quadrature of the continuous
observer, its disturbance estimate against a planted constant, the differentiator's settings as
they determine the estimates, and the package's lazily loaded names."""

from __future__ import annotations

import importlib

import numpy as np
import pytest
from scipy.integrate import solve_ivp

from maglev_oc.estimation.differentiate import HighGainDifferentiator
from maglev_oc.estimation.extended_high_gain import ExtendedHighGainObserver
from maglev_oc.model.stage import StageModel

TS = 2e-4  # [s] the rig's 5 kHz loop
EPS = 2e-3  # [s] the observer's time constant


@pytest.mark.parametrize(("y", "acc"), [(1e-4, 0.0), (0.0, 3.0), (-2e-4, -1.5)])
def test_the_innovation_integral_is_the_continuous_observers_over_one_sample(y, acc):
    """I(Ts) = int_0^Ts (y - p(t)) dt for the observer p' = q + a1/eps (y - p), q' = a2/eps^2 (y - p)
    + a, with the reading y and the acceleration a held over the sample: integrated here by an
    adaptive Runge-Kutta method (tolerance 1e-13 relative), against the observer's exact matrix
    exponential. Agreement to 1e-7 of the integral's scale (the integrator's tolerance); a wrong
    sign of either input's part changes it by all of that part."""
    est = ExtendedHighGainObserver(StageModel(), TS, EPS)
    a1, a2 = est.observer.alpha
    start = np.array([3e-5, -0.02])  # (p, q) [m, m/s]

    def rhs(_, s):
        p, q, _i = s
        return [q + a1 / EPS * (y - p), a2 / EPS**2 * (y - p) + acc, y - p]

    sol = solve_ivp(rhs, (0.0, TS), [*start, 0.0], method="DOP853", rtol=1e-13, atol=1e-18)
    want = sol.y[2, -1]
    got = float(est._innovation_integral(start, y, acc))
    scale = max(abs(y) + abs(start[0]), abs(acc) * TS**2, 1e-12) * TS
    assert got == pytest.approx(want, abs=1e-7 * scale)


def test_a_constant_disturbance_is_estimated_with_its_sign():
    """The plant at rest held by a constant extra acceleration (a guide force): the observer, told
    the model's acceleration at the current that holds the stage in the model (zero extra force),
    reads the stage still and must attribute the difference to d. At rest the model plus d must
    balance: d = -(model's acceleration). Within 1e-6 after 1 s (30 time constants of w_d)."""
    import casadi as ca

    model = StageModel()
    est = ExtendedHighGainObserver(model, TS, EPS, bandwidth=30.0, limit=5.0)
    obs, d = ca.SX.sym("o", 4), ca.SX.sym("d", 2)
    yy, uu = ca.SX.sym("y", 2), ca.SX.sym("u", 2)
    step = ca.Function("s", [obs, d, yy, uu], list(est.update(obs, d, yy, uu)))
    y = np.array([0.02, 0.01])
    u = np.array([0.3, 1.2])  # not the equilibrium: the model accelerates the still stage
    acc = np.asarray(model.f(np.array([y[0], 0.0, y[1], 0.0]), u)).ravel()
    o, dd = np.array([y[0], 0.0, y[1], 0.0]), np.zeros(2)
    for _ in range(5000):
        o, dd = (np.asarray(v).ravel() for v in step(o, dd, y, u))
    assert np.max(np.abs(acc[[1, 3]])) < 5.0  # inside the clip, so the limit does not decide
    np.testing.assert_allclose(dd, -acc[[1, 3]], atol=1e-6)


def test_the_differentiators_settings_name_what_determined_the_estimates():
    """Derivatives.settings holds every parameter of the high-gain differentiator under its own
    name (what the reports and a saved identification print next to the velocities)."""
    diff = HighGainDifferentiator(1e-3, epsilon=3e-3, acceleration_epsilon=7e-3)
    out = diff(np.linspace(0.0, 1e-3, 50))
    assert out.settings["epsilon"] == 3e-3
    assert out.settings["acceleration_epsilon"] == 7e-3
    assert out.method == "high_gain_observer"


def test_the_package_loads_its_names_on_first_use_and_refuses_others():
    """``maglev_oc.estimation`` hands out its everyday names from their modules (the same objects)
    and raises AttributeError, naming the package, for anything else."""
    pkg = importlib.import_module("maglev_oc.estimation")
    for name in pkg.__all__:
        module = importlib.import_module(f"maglev_oc.estimation.{pkg._EXPORTS[name]}")
        assert getattr(pkg, name) is getattr(module, name)
    with pytest.raises(AttributeError, match=r"maglev_oc\.estimation.*no_such_name"):
        pkg.no_such_name  # noqa: B018
