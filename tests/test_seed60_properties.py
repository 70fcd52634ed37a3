"""Properties from the survivors of the seed-60 mutation run: reproducible refutations and the
options a study hands down.

* the 3-DOF refutation draws its multistart points from the seed it is given (the same seed, the
  same starts: a report's refuted level is reproducible);
* the eps-trend study's NPFSI runs each receive the options it is given (the zero-phase run's
  differentiator), at every epsilon of the papers.
"""

from __future__ import annotations

import numpy as np


def test_the_microstepper_refutation_draws_its_starts_from_the_seed_it_is_given(monkeypatch):
    from maglev_oc.region.microstepper import MicrostepperRegion

    seeds = []
    original = np.random.default_rng

    def recording(seed=None):
        seeds.append(seed)
        return original(seed)

    region = MicrostepperRegion(current_limit=20.0, stoppers=False)
    monkeypatch.setattr(np.random, "default_rng", recording)
    a = region.refute((0.0, 0.0, 0.010), starts=1, seed=7)
    b = region.refute((0.0, 0.0, 0.010), starts=1, seed=7)
    assert seeds == [7, 7]
    assert a[:2] == b[:2]
    assert (a[2] is None and b[2] is None) or np.array_equal(a[2], b[2])


def test_the_eps_trend_hands_its_options_to_every_npfsi_run(monkeypatch):
    from types import SimpleNamespace

    from maglev_oc.identification import eps_trend as E

    calls = []

    def npfsi(log, model, *, estimate, eps, **kw):
        calls.append((eps, kw))
        return SimpleNamespace(values={k: 1.0 for k in estimate}, success=True)

    monkeypatch.setattr(E, "npfsi", npfsi)
    marker = object()
    trend, ok = E._npfsi_trend("src", None, None, ("C1", "C2"), differentiator=marker)
    assert ok
    assert [e for e, _ in calls] == list(E.PAPER_EPSILONS)
    assert all(kw == {"differentiator": marker} for _, kw in calls)
    assert trend.values.shape == (2, len(E.PAPER_EPSILONS))
