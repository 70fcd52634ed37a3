"""Properties of the equilibria (``maglev_oc.model.equilibrium``), checked against the model's own
force balance and Brent's method's tolerance:

- an equilibrium is at the requested gap and position with x' = 0 there;
- ``current_limit`` refuses exactly the currents above it, on the magnitude (beyond the
  zero-current gap the holding current is negative); an impossible gap is refused naming it;
- ``gap_for_current`` inverts the equilibrium current for any current in range, and refuses a
  current just outside what its bracket holds.
"""

from __future__ import annotations

import math

import numpy as np
import pytest
from numpy.testing import assert_allclose

from maglev_oc.errors import InputError
from maglev_oc.model.equilibrium import NoEquilibriumError, equilibrium, equilibrium_currents, gap_for_current


# --- equilibria -----------------------------------------------------------------------------------
@pytest.mark.parametrize("position", [-0.04, 0.0, 0.0123])
def test_equilibrium_is_where_it_was_asked(model, position):
    """x = (gap, 0, position, 0), u = (0, i_d) and x' = 0 there (force balance, 1e-10 m/s^2)."""
    op = equilibrium(model, 0.018, position)
    assert op.gap == 0.018 and op.position == position
    assert op.x[1] == 0.0 and op.x[3] == 0.0 and op.u[0] == 0.0
    assert np.max(np.abs(model.dynamics(op.x, op.u))) < 1e-10


@pytest.mark.parametrize("current", [-0.5, 0.0, 1.5, 4.0])
def test_gap_for_current_inverts_the_equilibrium_curve(model, current):
    """gap_for_current(I) is the gap whose equilibrium current is I (Brent to 1e-12 m; the curve
    falls about 0.4 A/mm, so the current agrees to 1e-8 A)."""
    gap = gap_for_current(model, current)
    assert 5e-3 < gap < 35e-3
    assert_allclose(equilibrium_currents(model, [gap]).current[0], current, atol=1e-8)
    # the curve decreases with the gap: a larger current holds a smaller gap
    assert gap_for_current(model, current + 0.5) < gap


def test_current_limit_option_is_the_one_applied(model):
    """equilibrium(current_limit=...) refuses exactly the currents above the limit given."""
    need = float(equilibrium_currents(model, [0.012]).current[0])  # about 4.5 A
    assert equilibrium(model, 0.012, current_limit=need * 1.01).u[1] == pytest.approx(need)
    with pytest.raises(InputError, match="limit"):
        equilibrium(model, 0.012, current_limit=need * 0.99)


def test_equilibrium_current_limit_is_on_the_magnitude(model):
    """Above the zero-current gap (about 24.3 mm) the holding current is negative (measured
    -4.85 A at 40 mm, +7.24 A at 6 mm): a limit below |i_d| refuses it whatever its sign, and a
    limit above accepts it with the current of :func:`equilibrium_currents`."""
    for gap in (6e-3, 40e-3):
        current = float(equilibrium_currents(model, [gap]).current[0])
        with pytest.raises(NoEquilibriumError, match="beyond"):
            equilibrium(model, gap, current_limit=0.9 * abs(current))
        op = equilibrium(model, gap, current_limit=1.1 * abs(current))
        assert op.u[1] == current and op.u[0] == 0.0
    assert float(equilibrium_currents(model, [40e-3]).current[0]) < 0


@pytest.mark.parametrize("gap", [math.inf, -0.02, 0.0, math.nan])
def test_an_impossible_gap_is_refused_naming_it(model, gap):
    """A gap that is not positive and finite is refused, and the message shows that gap (an
    infinite one too, which a filter on gap > 0 alone would leave out: "got []")."""
    with pytest.raises(InputError, match="positive and finite") as err:
        equilibrium_currents(model, np.array([0.02, gap]))
    assert str(err.value).endswith(f"got {gap:g}")


def test_gap_for_current_refuses_just_outside_its_bracket(model):
    """The bracket 5-35 mm holds currents between i(35 mm) and i(5 mm); 10 mA beyond either end
    (a residual product of a few 0.01 A^2, far below 1) is refused as NoEquilibriumError, 10 mA
    inside is found, the equilibrium current there within 1e-9 A (brentq's xtol 1e-12 m times a
    slope of about 0.4 A/mm)."""
    lo_i, hi_i = equilibrium_currents(model, [35e-3, 5e-3]).current
    for current in (hi_i + 0.01, lo_i - 0.01):
        with pytest.raises(NoEquilibriumError, match="no gap"):
            gap_for_current(model, float(current))
    for current in (hi_i - 0.01, lo_i + 0.01):
        gap = gap_for_current(model, float(current))
        assert 5e-3 < gap < 35e-3
        assert_allclose(equilibrium_currents(model, [gap]).current[0], current, rtol=0, atol=1e-9)
