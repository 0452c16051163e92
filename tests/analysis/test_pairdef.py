"""The one pair definition (analysis/pairs.py), the fit bar (blockslider.judge_fit), the transient
rule and the study summary, on constructed series with known answers."""

from __future__ import annotations

import math
from dataclasses import fields

import numpy as np
import pytest

from gouge_cli.analysis.blockslider import FIT_MIN_R2, FIT_PERIOD_FACTOR, fit_block_slider, judge_fit
from gouge_cli.analysis.pairs import SLOW, PairDefinition, classify_pair
from gouge_cli.analysis.study import StudyRow, study_summary, transient_slips
from gouge_cli.io.slipcatalog import SlipEntry
from gouge_cli.model.slip_rule import WallSeries
from gouge_cli.workflows.study import parse_slips, study_window

V, K, M, SIG = 1e-3, 0.5, 2.0, 1.0
DUR = math.pi * math.sqrt(M / K)
T = np.arange(0.0, 60.0, 0.01)


def bump(t0, dur, amp):
    out = np.zeros_like(T)
    on = (T > t0) & (T < t0 + dur)
    out[on] = amp * np.sin(math.pi * (T[on] - t0) / dur)
    return out


def series(strength, v, t_main=25.0):
    """Wall series whose tau/sigma peaks at ``strength`` before ``t_main`` (spring law)."""
    x = np.concatenate(([0.0], np.cumsum(0.5 * (v[1:] + v[:-1]) * np.diff(T))))
    raw = K * (V * T - x) / SIG
    return WallSeries(T, x, v, raw + strength - raw[T <= t_main].max(), np.full_like(T, 0.17))


def classify(s_d, s_u, v_u, **kw):
    return classify_pair(series(s_d, bump(25.0, DUR, 0.1)), series(s_u, v_u), V, K, M, SIG, **kw)


@pytest.mark.parametrize("diff,expected", [(0.0, "tie"), (2.7e-5, "tie"), (-2.7e-5, "tie"), (9e-4, "tie"),
                                           (-9e-4, "tie"), (1.5e-3, "II"), (-1.5e-3, "I"), (0.02, "II")])
def test_type_thresholds(diff, expected):
    r = classify(0.22, 0.22 + diff, bump(25.0, DUR * 1.2, 0.06))
    assert r.type == expected
    assert r.strength_difference == pytest.approx(diff, abs=1e-5)   # both peak at the onset sample
    assert r.definition["strength_tol"] == 1e-3 and r.definition["main"] == "first"


def test_slow_slip_below_trigger_is_reported_with_its_peak():
    # run thresholds of the demo: trigger 5 V_s, extent 1.5 V_s -> slow trigger 3 V_s
    d = PairDefinition().with_(start_factor=5.0, end_factor=1.5)
    assert d.slow_trigger == 3.0
    r = classify(0.22, 0.23, bump(25.0, DUR * 2, 3.3 * V), definition=d)
    assert r.undrained_event == SLOW and r.criteria["slow"] and r.type == "II-C"
    assert r.undrained_peak_over_Vs == pytest.approx(3.3, rel=1e-3)
    assert "3.3 V_s" in r.note and "slow slip below trigger" in r.note
    assert r.peak_velocity_ratio == pytest.approx(3.3 * V / 0.1, rel=1e-3)
    still = classify(0.22, 0.23, bump(25.0, DUR, 2.5 * V), definition=d)    # under the slow trigger
    assert still.type == "none" and "2.5 V_s" in still.note
    flat = classify(0.22, 0.23, np.zeros_like(T), definition=d)
    assert flat.type == "none" and flat.undrained_event == "none"


def test_definition_reads_run_thresholds_and_refuses_bad_main():
    d = PairDefinition.for_run({"start_factor": 5.0, "end_factor": 1.5, "merge_gap": 300.0}, main="largest")
    assert (d.slips.start_factor, d.slips.end_factor, d.slips.merge_gap, d.main) == (5.0, 1.5, 300.0, "largest")
    assert d.rule(2e-3) == d.slips.with_(V_s=2e-3) and d.rule(2e-3).hi == 5.0 * 2e-3
    flat = d.to_dict()
    assert (flat["start_factor"], flat["merge_gap"], flat["main"], flat["slow_trigger"]) == (5.0, 300.0, "largest", 3.0)
    assert "slips" not in flat
    with pytest.raises(ValueError, match="main"):
        PairDefinition(main="biggest")


def test_definition_for_run_refuses_an_unknown_key_naming_it():
    """A misspelt override is refused, not ignored (it would leave the default in force)."""
    with pytest.raises(TypeError, match="'strenght_tol'"):
        PairDefinition.for_run({"start_factor": 5.0}, strenght_tol=1e-2)
    with pytest.raises(TypeError, match="'lead_stress'.*strength_tol"):      # a slips key that is not the rule's
        PairDefinition.for_run({"start_factor": 5.0, "lead_stress": 0.1})
    assert PairDefinition.for_run({"start_factor": 5.0}, strength_tol=None).strength_tol == 1e-3    # None: kept


def test_fit_bar_sine_passes_noise_and_wrong_period_fail():
    t = np.arange(0.0, 40.0, 0.01)
    v = np.where((t > 5) & (t < 5 + DUR), 0.1 * np.sin(math.pi * (t - 5) / DUR), 0.0)
    i0, i1 = int(5.01 / 0.01), int((5 + DUR - 0.01) / 0.01)
    good = fit_block_slider(t, v, (i0, i1), K, M, SIG)
    assert good.success and good.reason == "" and good.r2 > 0.999
    assert good.m_eff == pytest.approx(M, rel=1e-3)           # k (T_fit / pi)^2 of a rigid block
    noise = np.random.default_rng(0).uniform(0.0, 0.1, t.size)
    bad = fit_block_slider(t, noise, (i0, i1), K, M, SIG)
    assert not bad.success and "R^2" in bad.reason and bad.r2 < FIT_MIN_R2
    # the rising quarter of a sine 10x longer: fits well, but its half period is ~20x the window
    slow = 0.1 * np.sin(math.pi * (t - 5) / (20 * DUR))
    j1 = int((5 + DUR) / 0.01)
    long_fit = fit_block_slider(t, slow, (i0, j1), K, M, SIG)
    assert not long_fit.success and "half period" in long_fit.reason
    assert judge_fit(0.95, 10.0, 10.0 * FIT_PERIOD_FACTOR * 1.01)[0] is False
    assert judge_fit(0.95, 10.0, 10.0 * FIT_PERIOD_FACTOR * 0.99) == (True, "")


def test_transient_rule():
    cat = [SlipEntry.from_attrs({"number": i + 1, "static_strength": s, "stress_drop": d}) for i, (s, d) in enumerate(
        [(0.40, 0.20), (0.15, 0.01), (0.31, 0.10), (0.20, 0.02), (0.30, 0.11), (0.32, 0.09), (0.29, 0.10)])]
    assert transient_slips(cat) == {1, 2}            # slip 3 is the first near the late medians
    assert transient_slips(cat[:1]) == {1}
    assert transient_slips([]) == set()


def test_study_summary_leaves_transient_rows_out():
    def row(slip, typ, transient=False, pv=0.8, dur=100.0, r2=0.95, ok=True, meff=4.0, r2n=0.97):
        unset = {f.name: float("nan") for f in fields(StudyRow)}
        return StudyRow(**dict(unset, slip=slip, transient=transient, type=typ, undrained_event="slip",
                               peak_velocity_ratio=pv, stress_drop_ratio=0.9, drained_duration=dur,
                               drained_fit_r2=r2, drained_fit_ok=ok, drained_fit_r2_notched=r2n,
                               m_eff_over_m_b=meff if ok else float("nan")))

    rows = [row(1, "I", transient=True, pv=2.0, dur=10.0), row(2, "II-C", r2=0.85), row(3, "I"),
            row(4, "tie", pv=1.2, r2n=0.8), row(5, "II", dur=130.0, r2=0.3, ok=False)]
    s = study_summary(rows)
    assert (s.n, s.n_type_I, s.n_type_II, s.n_tie, s.n_complex) == (4, 1, 2, 1, 1)
    assert s.frac_slower == 0.75 and s.drained_frac_fit_ok == 0.75
    assert s.drained_frac_r2_good == 0.5 and s.drained_frac_duration_within == 0.75
    assert s.drained_frac_r2_good_notched == 0.5      # slips 2 and 3 (4's notched R^2 0.8, 5 fails the bar)
    assert s.m_eff_over_m_b.mean == 4.0 and s.m_eff_over_m_b.n == 3


def test_parse_slips_and_window():
    assert parse_slips("3-5,9") == [3, 4, 5, 9] and parse_slips(None) is None
    with pytest.raises(ValueError):
        parse_slips("5-3")
    entry = SlipEntry.from_attrs({"number": 1, "end_time": 1000.0, "duration": 100.0})
    assert study_window(entry, 400.0, 3e-4, 1e-6, 1e-4) == pytest.approx(600 + 200 + 0.05 * 3e-4 / 1e-10)


def test_order_flag_marks_errors_that_do_not_fall():
    from gouge_cli.studies.accuracy import fit_order, order_flag

    assert order_flag([0.4, 0.2, 0.1], [1.6e-3, 4e-4, 1e-4]) == ""                 # clean second order
    flag = order_flag([0.8, 0.4, 0.2, 0.1], [2.9e-3, 2.8e-3, 6.2e-4, 4.4e-4][::-1])
    assert "do not fall" in flag
    # the README's demo ladder, wall velocity: 0.018, 0.028, 0.011, 6.5e-3 at dt_safety 0.8 .. 0.1
    assert "do not fall" in order_flag([0.8, 0.4, 0.2, 0.1], [0.018, 0.028, 0.011, 6.5e-3])
    assert math.isfinite(fit_order([0.8, 0.4, 0.2, 0.1], [0.018, 0.028, 0.011, 6.5e-3]))   # a number all the same
    assert "R^2" in order_flag([1.0, 0.5, 0.25, 0.125], [1.0, 0.99, 0.98, 1e-3])
    assert order_flag([0.4], [1e-3]) == "fewer than 2 errors"
