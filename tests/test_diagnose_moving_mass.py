"""Constants that moved together as a payload moves them (``maglev_oc.identification.masses``).

The lumped constants are forces per moving mass: a payload of m kg lowers C1 by M_h / (M_h + m)
and C2..C4 by M_v / (M_v + m). Before this was read, a log of the independent generator whose
movers were 1 kg heavier was diagnosed with the warning that something the model lacks (guide
friction, a detent, a cable carrier) takes C1's place; there was none.
"""

from __future__ import annotations

import numpy as np
import pytest

from maglev_oc.data.reading import read_log
from maglev_oc.diagnosis.pipeline import diagnose
from maglev_oc.identification.masses import MIN_MASS_CHANGE, moving_mass_change
from maglev_oc.model.stage import StageModel
from maglev_oc.results import Estimate
from tests.independent.logio import write_log
from tests.independent.physics import GEOMETRY
from tests.independent.simulate import Scenario, draw_constants, simulate

MODEL = StageModel()
REFERENCE = dict(zip(("C1", "C2", "C3", "C4"), MODEL.constants.as_array(), strict=True))
M_H, M_V = MODEL.params.mass_horizontal, MODEL.params.mass_vertical


def _constants(factors: tuple[float, float, float, float], stderr: float = 0.0) -> dict[str, Estimate]:
    return {
        c: Estimate(REFERENCE[c] * f, stderr * REFERENCE[c], "")
        for c, f in zip(("C1", "C2", "C3", "C4"), factors, strict=True)
    }


def _payload(m: float) -> tuple[float, float, float, float]:
    h, v = M_H / (M_H + m), M_V / (M_V + m)
    return (h, v, v, v)


# --- the reading ----------------------------------------------------------------------------------
@pytest.mark.parametrize("m", [0.4, 0.8, 2.0, -0.4])
def test_a_payload_s_constants_give_its_mass(m):
    # exact constants of movers m kg heavier (or lighter): m to rounding, and each constant's factor
    found = moving_mass_change(_constants(_payload(m)), REFERENCE, MODEL.params)
    assert found is not None and found.added.value == pytest.approx(m, abs=1e-4)
    assert found.factor("C1") == pytest.approx(_payload(m)[0], rel=1e-4)
    assert found.factor("C4") == pytest.approx(_payload(m)[3], rel=1e-4)


@pytest.mark.parametrize(
    ("factors", "what"),
    [
        ((0.9, 0.81, 0.9, 1.0), "magnets 10 % weaker: C1, C3 with the field, C2 with its square"),
        ((0.6, 1.0, 1.0, 1.0), "C1 alone 40 % low (friction or a detent taking current)"),
        ((0.905, 0.933, 0.935, 1.083), "a plant 6.5-9.5 % below the papers' (experiments_53)"),
        ((0.96, 1.03, 0.97, 1.0), "a plant a few per cent off the papers', signs mixed"),
        (_payload(0.25), "a payload of 0.25 kg: within a rig's own difference"),
    ],
)
def test_constants_that_moved_otherwise_are_no_payload(factors, what):
    assert moving_mass_change(_constants(factors), REFERENCE, MODEL.params) is None, what


def test_the_smallest_mass_read_is_beyond_a_rigs_own_difference():
    # with every constant of the plant 4 % off the papers' (the generator's widest draw) against the
    # payload, the reading is still within 0.15 kg of it, and no smaller payload than
    # MIN_MASS_CHANGE is read
    m = 0.6
    worst = tuple(f * (1.04 if k == 0 else 0.96) for k, f in enumerate(_payload(m)))
    found = moving_mass_change(_constants(worst), REFERENCE, MODEL.params)
    assert found is not None and abs(found.added.value - m) < 0.15
    assert moving_mass_change(_constants(_payload(0.9 * MIN_MASS_CHANGE)), REFERENCE, MODEL.params) is None


def test_the_vertical_constants_alone_read_a_payload_whatever_c1_did():
    # C2 and C3 asked alone (the thrust-restoring pairs' payload, selection._carried_vertically):
    # a payload's vertical factors give its mass whatever C1 is (set 30200 of the independent
    # generator: 0.8 kg with C1 at 3.5 beside a commutation offset and a spring), and not 0.25 kg.
    # They cannot tell a weaker field from a payload: the magnets 10 % weaker (C2 with the field's
    # square, C3 with the field) read as 0.74 kg. That is why the payload is read only when C1 agrees,
    # and the selection takes the vertical reading as one more C1 a thrust-restoring pair may reach,
    # not as a payload
    for c1 in (0.25, 1.0):
        factors = (c1, *_payload(0.8)[1:])
        found = moving_mass_change(_constants(factors), REFERENCE, MODEL.params, asked=("C2", "C3"))
        assert found is not None and found.added.value == pytest.approx(0.8, abs=1e-4)
        assert found.factor("C1") == pytest.approx(_payload(0.8)[0], rel=1e-4)
        assert moving_mass_change(_constants(factors), REFERENCE, MODEL.params) is None  # C1 asked too
    weaker = _constants((0.9, 0.81, 0.9, 1.0))
    assert moving_mass_change(weaker, REFERENCE, MODEL.params, asked=("C2", "C3")).added.value > 0.7
    assert moving_mass_change(weaker, REFERENCE, MODEL.params) is None
    small = _payload(0.25)
    assert moving_mass_change(_constants(small), REFERENCE, MODEL.params, asked=("C2", "C3")) is None


# --- a log of a stage carrying a payload ----------------------------------------------------------
def test_a_payload_is_read_as_such_not_as_something_the_model_lacks(tmp_path):
    # the generator's plant with its constants those of movers 1 kg heavier (C1 -39 %, C2..C4
    # -19 %; the plant itself 1-4 % off the papers', seed 7801): nothing claimed, no warning of a
    # constant no stage has (there was: "C1 ... 41 % below the model's ... guide friction, a detent,
    # a cable carrier ... take current"), the mass read within 0.15 kg (2.5 of its standard errors:
    # the plant's own few per cent), in the JSON and the result's words; and by identify (which
    # warned "C1 = 8.457 is 40 % below its starting value ...")
    m = 1.0
    base = draw_constants(np.random.default_rng(7801), (0.01, 0.04))
    h, v = GEOMETRY.M_h / (GEOMETRY.M_h + m), GEOMETRY.M_v / (GEOMETRY.M_v + m)
    run = simulate(
        Scenario(name="payload", seed=7801, constants=(base[0] * h, base[1] * v, base[2] * v, base[3] * v))
    )
    path = write_log(run, tmp_path)[0]
    d = diagnose([read_log(path)], limits=False)
    assert not d.effects and not d.warnings
    assert d.moving_mass is not None and abs(d.moving_mass.added.value - m) < 0.15
    j = d.to_dict()["moving_mass"]
    assert j["added_kg"] == pytest.approx(d.moving_mass.added.value) and "payload" in j["reading"]
    assert "moving mass:" in d.report()
    # identify reads it from its own fit, and warns of nothing either
    from maglev_oc.identification.pipeline import identify

    out = identify([read_log(path)], MODEL, methods=("equation_error",))
    assert not out.warnings and abs(out.moving_mass.added.value - m) < 0.15
    assert out.to_dict()["moving_mass"]["added_kg"] == pytest.approx(out.moving_mass.added.value)
