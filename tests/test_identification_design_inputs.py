"""Bad input to the experiment designer (``maglev_oc.identification.design``) gets a clear
``InputError`` naming the field, at the boundary each check states and not one step inside it
(lines coverage found no test reaching; a bound moved by one comparison would pass every other
test). Good input exactly at a bound is accepted."""

from __future__ import annotations

import math

import numpy as np
import pytest
import scipy.io

from maglev_oc.errors import InputError
from maglev_oc.identification import design as D
from maglev_oc.model.stage import StageModel


def test_the_feasible_sets_bounds_need_lower_below_upper_and_currents_in_order():
    for name in ("gap", "position", "true_gap", "true_position"):
        lo, _ = getattr(D.FeasibleSet(), name)
        with pytest.raises(InputError, match=rf"FeasibleSet\.{name}: need lower < upper"):
            D.FeasibleSet(**{name: (lo, lo)})
        D.FeasibleSet(**{name: (lo, math.nextafter(lo, math.inf))})
    peak = D.FeasibleSet().peak_current
    D.FeasibleSet(continuous_current=peak)  # equal is allowed ("<=")
    for continuous in (0.0, math.nextafter(peak, math.inf)):
        with pytest.raises(InputError, match="0 < continuous_current <= peak_current"):
            D.FeasibleSet(continuous_current=continuous)


def test_a_constant_signal_has_no_crest_factor():
    with pytest.raises(InputError, match="crest_factor: the signal is constant"):
        D.crest_factor(np.full(10, 3.0))
    assert D.crest_factor(np.array([1.0, -1.0, 1.0, -1.0])) == pytest.approx(1.0, rel=1e-12)


def test_the_multisine_clipping_passes_are_a_non_negative_integer():
    D.multisine([1, 2], [1.0, 0.5], clip_passes=0)
    for bad in (-1, 1.0):
        with pytest.raises(InputError, match="clip_passes must be a non-negative integer"):
            D.multisine([1, 2], [1.0, 0.5], clip_passes=bad)


def test_a_prbs_order_is_an_integer_from_3_to_20():
    assert D.prbs(3).size == 7
    assert D.prbs(20).size == 2**20 - 1
    for bad in (2, 21, 3.0):
        with pytest.raises(InputError, match=r"order must be an integer in 3\.\.20"):
            D.prbs(bad)


def test_a_multisine_shape_needs_a_band_from_zero_up_and_whole_tones():
    D.MultisineShape(band=(1e-9, 2e-9), tones=1)
    for band in ((0.0, 1.0), (1.0, 1.0), (0.1, math.inf)):
        with pytest.raises(InputError, match=r"MultisineShape\.band: need 0 < low < high"):
            D.MultisineShape(band=band)
    for tones in (0, 2.0):
        with pytest.raises(InputError, match=r"MultisineShape\.tones must be a positive integer"):
            D.MultisineShape(tones=tones)


def test_prbs_bits_and_gap_sweeps_need_a_positive_time():
    with pytest.raises(InputError, match="bit_time must be positive"):
        D.prbs_reference(20.0, bit_time=(0.0, 0.5))
    with pytest.raises(InputError, match="bit_time must be positive"):
        D.prbs_reference(20.0, bit_time=(0.25, -1.0))
    with pytest.raises(InputError, match="sweep_period must be positive"):
        D.gap_sweep_reference(20.0, sweep_period=0.0)
    for gaps in ((0.0, 0.02), (0.02, 0.02), (0.01, math.nextafter(0.1, 1.0))):
        with pytest.raises(InputError, match="gaps must be"):
            D.gap_sweep_reference(20.0, gaps=gaps)


def test_the_designer_needs_a_finite_non_negative_residual_floor():
    model = StageModel()
    assert D.ExperimentDesigner(model, residual_floor=0.0).residual_floor == 0.0
    for bad in (-1e-12, math.inf, math.nan):
        with pytest.raises(InputError, match="residual_floor must be non-negative"):
            D.ExperimentDesigner(model, residual_floor=bad)


def test_a_design_needs_a_known_kind_and_a_duration_from_10_s_to_an_hour():
    with pytest.raises(InputError, match="kind must be one of"):
        D.design_experiment("chirp", 60.0)
    for duration in (math.nextafter(10.0, 0.0), math.nextafter(3600.0, math.inf), math.nan, "60"):
        with pytest.raises(InputError, match="duration must be between 10 and 3600 s"):
            D.design_experiment("prbs", duration)
    # the shortest accepted (a 10 s PRBS design, about 3 s)
    design = D.design_experiment("prbs", 10.0)
    assert design.success and design.reference.t[-1] == pytest.approx(10.0, abs=2e-3)


def test_an_empty_d_optimal_grid_is_refused():
    with pytest.raises(InputError, match="the D-optimal grid is empty"):
        D._doptimal(None, 60.0, None, [])


def test_a_design_is_written_into_a_folder_only(tmp_path):
    target = tmp_path / "design"
    target.write_text("not a folder", encoding="utf-8")
    with pytest.raises(InputError, match="is a file; --out takes a folder"):
        D.write_design(target, None)
    assert target.read_text(encoding="utf-8") == "not a folder"  # left as it was


def test_a_reference_file_must_carry_every_column(tmp_path):
    columns = list(D.REFERENCE_COLUMNS)
    mat = tmp_path / "reference.mat"
    scipy.io.savemat(mat, {c: np.zeros(3) for c in columns[:-1]})
    with pytest.raises(InputError, match=rf"missing variables \['{columns[-1]}'\]"):
        D.read_reference(mat)
    csv = tmp_path / "reference.csv"
    csv.write_text(
        "# a comment\n" + ",".join(columns[::-1]) + "\n" + ",".join("0" * len(columns)) + "\n",
        encoding="utf-8",
    )
    with pytest.raises(InputError, match=r"header .* is not"):
        D.read_reference(csv)


def test_a_sampled_reference_is_read_only_and_leaves_the_callers_arrays_alone():
    # a reference file's samples are data: the reference holds read-only copies, so neither a later
    # write through it nor the caller's own arrays can change what was designed and written
    t = np.arange(5) * 1e-3
    values = np.zeros((6, 5))
    values[0] = 0.015
    ref = D.SampledReference(t, values)
    for held in (ref.t, ref.values):
        assert not held.flags.writeable
        with pytest.raises(ValueError, match="read-only"):
            held[0] = 1.0
    assert t.flags.writeable and values.flags.writeable
    t[1] = 0.5
    values[0, 0] = 0.02
    assert ref.t[1] == 1e-3 and ref.values[0, 0] == 0.015
