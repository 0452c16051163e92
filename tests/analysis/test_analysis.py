"""Tests for gouge_cli.analysis: slips, block-slider fit, friction (Eqs. 5-7), pair types."""

from __future__ import annotations

import json
import math
import pickle

import numpy as np
import pytest

from gouge_cli.analysis import (
    SlipDetector,
    WallSeries,
    block_slider_prediction,
    campaign_summary,
    classify_pair,
    detect_slips,
    dynamic_friction,
    effective_pressure,
    estimate_natural_frequency,
    fit_block_slider,
    mean_dynamic_friction,
    recurrence_intervals,
    shear_resistance,
    simulate_block_slider,
    spring_stress,
)

# Block slider: omega = sqrt(k/m) = 0.5, duration 2 pi, peak 0.1 = 500 V_s,
# slip 0.4, recurrence 2000.
M, K, SIGMA, MU_S, MU_D, VS = 2.0, 0.5, 1.0, 0.6, 0.5, 2e-4
DMU = MU_S - MU_D


@pytest.fixture(scope="module")
def slider():
    return simulate_block_slider(M, K, SIGMA, MU_S, MU_D, VS, dt=0.02, t_end=14000.0)


@pytest.fixture(scope="module")
def slider_slips(slider):
    return detect_slips(slider["t"], slider["v_wall"], VS, x_wall=slider["x_wall"],
                        tau_over_sigma=slider["tau_over_sigma"])


def _rel(a, b):
    return abs(a - b) / abs(b)


# --------------------------------------------------------------- block slider


def test_fit_clean_sine_recovers_half_period_amplitude_and_dmu():
    V_s, A, T = 1e-3, 0.05, 7.0
    k, sigma = 0.2, 1.0
    m_b = k * (T / math.pi) ** 2
    dt = 0.01
    t = np.arange(0.0, 40.0, dt)
    v = np.full_like(t, V_s)
    on = (t > 10.0) & (t < 10.0 + T)
    v[on] = np.maximum(A * np.sin(math.pi * (t[on] - 10.0) / T), V_s)
    slips = detect_slips(t, v, V_s)
    assert len(slips) == 1
    fit = fit_block_slider(t, v, slips[0], k=k, m_b=m_b, sigma=sigma)
    assert fit.success
    assert _rel(fit.half_period, T) < 0.01
    assert _rel(fit.amplitude, A) < 0.01
    assert fit.r2 > 0.99
    assert fit.nrms < 0.01
    assert _rel(fit.predicted_half_period, T) < 1e-12
    assert abs(fit.half_period_ratio - 1.0) < 0.01
    planted_dmu = A * math.sqrt(k * m_b) / sigma
    assert _rel(fit.delta_mu, planted_dmu) < 0.01
    assert _rel(fit.period, 2 * T) < 0.01


def test_fit_rejects_wrong_shape():
    t = np.arange(0.0, 10.0, 0.01)
    v = np.where((t > 2) & (t < 8), 1.0, 0.0)
    v[(t > 4.5) & (t < 5.5)] = 0.05
    fit = fit_block_slider(t, v, (int(2.05 / 0.01), int(7.95 / 0.01)))
    assert fit.r2 < 0.8


def test_block_slider_events_match_analytic(slider_slips):
    pred = block_slider_prediction(DMU, SIGMA, K, M, VS)
    slips = slider_slips
    assert len(slips) == 4
    for s in slips:
        assert _rel(s.duration, pred["duration"]) < 0.02
        assert _rel(s.peak_velocity, pred["peak_velocity"]) < 0.02
        assert _rel(s.slip, pred["slip"]) < 0.02
        assert _rel(s.static_strength, MU_S) < 1e-3
        assert _rel(s.stress_drop, 2 * DMU) < 0.02
        assert s.n_subevents == 1
        assert abs(s.peak_time - (s.onset_time + s.end_time) / 2) < 0.05 * s.duration
    rec = recurrence_intervals(slips)
    assert rec.shape == (3,)
    assert np.all(np.abs(rec - pred["recurrence"]) < 0.02 * pred["recurrence"])
    assert _rel(slips[0].onset_time, MU_S * SIGMA / (K * VS)) < 1e-3


def test_block_slider_fit_on_simulated_slips(slider, slider_slips):
    for s in slider_slips:
        fit = fit_block_slider(slider["t"], slider["v_wall"], s, K, M, SIGMA)
        assert fit.r2 > 0.999
        assert abs(fit.half_period_ratio - 1) < 0.01
        assert _rel(fit.delta_mu, DMU) < 0.01


# ------------------------------------------------------------------- friction


def _middle(t, slips, frac=0.25):
    sel = np.zeros(t.size, bool)
    for s in slips:
        d = s.duration
        sel |= (t >= s.onset_time + frac * d) & (t <= s.end_time - frac * d)
    return sel


@pytest.mark.parametrize("method", ["velocity", "displacement"])
def test_dynamic_friction_recovers_planted_mu_d(slider, slider_slips, method):
    t = slider["t"]
    mu = dynamic_friction(t, slider["v_wall"], M, SIGMA, x_wall=slider["x_wall"],
                          V_s=VS, k=K, method=method)
    mid = _middle(t, slider_slips)
    assert mid.sum() > 500
    assert np.max(np.abs(mu[mid] - MU_D)) < 0.01 * MU_D
    for s in slider_slips:
        assert abs(mean_dynamic_friction(t, mu, s) - MU_D) < 0.002 * MU_D
    stuck = slider["v_wall"] == 0
    stuck[1:-1] &= stuck[:-2] & stuck[2:]
    assert np.allclose(mu[stuck], slider["tau_over_sigma"][stuck], atol=1e-9)


def test_dynamic_friction_from_tau_series_and_resistance(slider, slider_slips):
    t = slider["t"]
    mu_x = dynamic_friction(t, slider["v_wall"], M, SIGMA, x_wall=slider["x_wall"], V_s=VS, k=K)
    mu_tau = dynamic_friction(t, slider["v_wall"], M, SIGMA,
                              tau_over_sigma=slider["tau_over_sigma"])
    np.testing.assert_allclose(mu_x, mu_tau, atol=1e-12)
    r = shear_resistance(t, slider["v_wall"], M, x_wall=slider["x_wall"], V_s=VS, k=K)
    np.testing.assert_allclose(r, mu_x * SIGMA, atol=1e-12)
    np.testing.assert_allclose(spring_stress(t, slider["x_wall"], VS, K),
                               slider["tau_over_sigma"] * SIGMA, atol=1e-12)
    p = effective_pressure(0.5 * (SIGMA - 0.1), 0.5, SIGMA)
    assert abs(p - 0.1) < 1e-12


def test_notch_filter_removes_layer_vibration(slider, slider_slips):
    t, v, x = slider["t"], slider["v_wall"].copy(), slider["x_wall"].copy()
    f_n, eps = 2.0, 2e-3
    w = 2 * math.pi * f_n
    sliding = v > 0
    v[sliding] += eps * np.sin(w * t[sliding])
    x[sliding] += -eps / w * np.cos(w * t[sliding])
    mid = _middle(t, slider_slips)
    raw = dynamic_friction(t, v, M, SIGMA, x_wall=x, V_s=VS, k=K)
    assert abs(estimate_natural_frequency(t, raw, f_min=0.5) - f_n) < 0.02 * f_n
    s = slider_slips[1]
    win = slice(s.onset_index - 200, s.end_index + 200)
    assert abs(estimate_natural_frequency(t[win], raw[win], f_min=0.5) - f_n) < 0.02 * f_n
    auto = dynamic_friction(t, v, M, SIGMA, x_wall=x, V_s=VS, k=K, notch="auto")
    fixed = dynamic_friction(t, v, M, SIGMA, x_wall=x, V_s=VS, k=K, notch=f_n)
    err_raw = np.std(raw[mid] - MU_D)
    assert err_raw > 0.05 * MU_D
    assert np.std(auto[mid] - MU_D) < err_raw / 5
    assert np.std(fixed[mid] - MU_D) < err_raw / 5


# ---------------------------------------------------------------- detection


def _bump(t, t0, dur, amp):
    out = np.zeros_like(t)
    on = (t > t0) & (t < t0 + dur)
    out[on] = amp * np.sin(math.pi * (t[on] - t0) / dur)
    return out


def test_detection_thresholds_and_edges():
    V_s, dt = 1e-3, 0.01
    t = np.arange(0.0, 100.0, dt)
    v = (_bump(t, -2.0, 6.0, 0.1)          # running at the first sample: ignored
         + _bump(t, 10.0, 5.0, 0.008)      # peak 8 V_s < 10 V_s: no trigger
         + _bump(t, 30.0, 5.0, 0.05)       # a slip
         + _bump(t, 97.0, 6.0, 0.1))       # unfinished at the end: ignored
    slips = detect_slips(t, v, V_s)
    assert len(slips) == 1
    s = slips[0]
    lag = 5.0 / math.pi * math.asin(2 * V_s / 0.05)
    assert abs(s.onset_time - (30.0 + lag)) < 1e-3 and abs(s.end_time - (35.0 - lag)) < 1e-3
    assert abs(s.slip - 2 * 0.05 * 5.0 / math.pi) < 1e-3
    assert math.isnan(s.static_strength) and math.isnan(s.porosity_change)
    assert abs(s.mean_velocity - s.slip / s.duration) < 1e-15
    assert len(detect_slips(t, v, V_s, start_factor=7.0)) == 2
    assert detect_slips(t, v, V_s, min_slip=0.2) == []
    assert detect_slips(t, v, V_s, min_duration=6.0) == []
    with pytest.raises(ValueError):
        detect_slips(t, v, V_s, start_factor=2.0, end_factor=2.0)


def test_merge_gap_and_subevents():
    V_s, dt = 1e-3, 0.01
    t = np.arange(0.0, 60.0, dt)
    v = _bump(t, 10.0, 4.0, 0.1) + _bump(t, 14.5, 4.0, 0.08)
    assert len(detect_slips(t, v, V_s)) == 2
    merged = detect_slips(t, v, V_s, merge_gap=1.0)
    assert len(merged) == 1
    s = merged[0]
    assert s.n_merged == 2 and s.n_subevents == 2
    assert [round(e.time, 2) for e in s.subevents] == [12.0, 16.5]
    # A dip that stays above the start threshold but below half the peaks.
    dip = 1 - 0.7 * np.exp(-(((t - 20.0) / 0.4) ** 2))
    single = detect_slips(t, _bump(t, 17.0, 6.0, 0.1) * dip, V_s)
    assert len(single) == 1 and single[0].n_subevents == 2
    shallow = 1 - 0.3 * np.exp(-(((t - 20.0) / 0.4) ** 2))
    assert detect_slips(t, _bump(t, 17.0, 6.0, 0.1) * shallow, V_s)[0].n_subevents == 1


def _noisy_series(seed=0, n=40000, dt=0.01):
    rng = np.random.default_rng(seed)
    t = np.arange(n) * dt
    V_s = 1e-3
    v = 0.3 * V_s * rng.standard_normal(n)
    v += _bump(t, -1.0, 3.0, 0.05)
    for t0 in np.arange(5.0, t[-1] - 3.0, 9.0):
        dur = rng.uniform(1.0, 4.0)
        v += _bump(t, t0, dur, rng.uniform(0.003, 0.08))
        if rng.random() < 0.6:
            v += _bump(t, t0 + dur + rng.uniform(-0.5, 1.5), rng.uniform(0.5, 2.0),
                       rng.uniform(0.005, 0.05))
    v += _bump(t, t[-1] - 1.0, 3.0, 0.05)
    v += 0.004 * np.sin(2 * math.pi * 3.0 * t) * (v > 0.01)
    x = np.concatenate(([0.0], np.cumsum(0.5 * (v[1:] + v[:-1]) * dt)))
    tau = 0.2 + 0.01 * (V_s * t - x) + 1e-4 * rng.standard_normal(n)
    tau[rng.random(n) < 0.01] = np.nan
    phi = 0.17 + 1e-3 * np.cumsum(rng.standard_normal(n)) / math.sqrt(n)
    return t, x, v, tau, phi, V_s


def _stream(t, x, v, tau, phi, det, cut=None):
    out = []
    for i in range(t.size):
        if cut is not None and i == cut:
            det = SlipDetector.from_state_dict(json.loads(json.dumps(det.state_dict())))
            det = pickle.loads(pickle.dumps(det))
        s = det.update(t[i], x[i], v[i], tau[i], phi[i])
        if s is not None:
            out.append(s)
    s = det.flush()
    if s is not None:
        out.append(s)
    return out


@pytest.mark.parametrize("kw", [
    {},
    {"merge_gap": 1.0},
    {"merge_gap": 2.5, "strength_window": 3.0, "min_slip": 0.01},
    {"start_factor": 20.0, "end_factor": 1.0, "merge_gap": 0.3, "min_duration": 0.5,
     "subevent_fraction": 0.7, "min_subevent_fraction": 0.0},
])
def test_streaming_equals_batch(kw):
    t, x, v, tau, phi, V_s = _noisy_series()
    batch = detect_slips(t, v, V_s, x_wall=x, tau_over_sigma=tau, porosity=phi, **kw)
    stream = _stream(t, x, v, tau, phi, SlipDetector(V_s, **kw), cut=t.size // 3)
    assert len(batch) >= 5
    assert len(stream) == len(batch)
    np.testing.assert_equal([s.to_dict() for s in stream], [s.to_dict() for s in batch])
    if kw.get("merge_gap"):
        assert any(s.n_merged > 1 for s in batch)
    assert any(s.n_subevents > 1 for s in batch)


def test_streaming_equals_batch_on_block_slider(slider, slider_slips):
    n = 450000
    sl = {k: slider[k][:n] for k in ("t", "x_wall", "v_wall", "tau_over_sigma")}
    batch = [s for s in slider_slips if s.end_index < n - 1]
    det = SlipDetector(VS)
    out, when = [], []
    for i in range(n):
        s = det.update(sl["t"][i], sl["x_wall"][i], sl["v_wall"][i], sl["tau_over_sigma"][i])
        if s is not None:
            out.append(s)
            when.append(i)
    assert len(out) == len(batch) == 2
    np.testing.assert_equal([s.to_dict() for s in out], [s.to_dict() for s in batch])
    assert when == [s.end_index + 1 for s in batch]


# ---------------------------------------------------------------------- pairs

PV, PK, PM, PSIG = 1e-3, 0.5, 2.0, 1.0
PDUR = math.pi * math.sqrt(PM / PK)


def _series(strength, v, t, t_main):
    x = np.concatenate(([0.0], np.cumsum(0.5 * (v[1:] + v[:-1]) * np.diff(t))))
    raw = PK * (PV * t - x) / PSIG
    c = strength - raw[t <= t_main].max()
    return WallSeries(t=t, x_wall=x, v_wall=v, tau_over_sigma=raw + c,
                      porosity=np.full_like(t, 0.17))


def _pair(s_d, s_u, v_u=None):
    t = np.arange(0.0, 60.0, 0.01)
    v_d = _bump(t, 25.0, PDUR, 0.1)
    v_u = _bump(t, 25.0, PDUR * 1.2, 0.06) if v_u is None else v_u(t)
    return _series(s_d, v_d, t, 25.0), _series(s_u, v_u, t, 25.0)


def _classify(d, u, **kw):
    return classify_pair(d, u, PV, PK, PM, PSIG, **kw)


def test_pair_types_from_planted_strengths():
    r1 = _classify(*_pair(0.22, 0.21))
    assert r1.type == "I" and not r1.complex
    assert abs(r1.drained_strength - 0.22) < 1e-3 and abs(r1.undrained_strength - 0.21) < 1e-3
    r2 = _classify(*_pair(0.22, 0.23))
    assert r2.type == "II" and not any(r2.criteria.values())
    assert abs(r2.peak_velocity_ratio - 0.6) < 0.01
    assert abs(r2.duration_ratio - 1.2) < 0.02
    assert 0 < r2.stress_drop_ratio < 1
    assert _classify(*_pair(0.22, 0.22)).type == "tie"
    assert _classify(*_pair(0.22, 0.2205), strength_tol=1e-3).type == "tie"


def test_pair_subevents_give_complex_via_criterion_a():
    def v_u(t):
        dip = 1 - 0.7 * np.exp(-(((t - 25.0 - PDUR * 0.6) / 0.4) ** 2))
        return _bump(t, 25.0, PDUR * 1.2, 0.06) * dip

    r = _classify(*_pair(0.22, 0.23, v_u))
    assert r.type == "II-C" and r.complex
    assert r.criteria["subevents"] and r.measures["n_subevents"] == 2
    assert not r.criteria["restart"] and not r.criteria["creep"]
    r_i = _classify(*_pair(0.22, 0.21, v_u))
    assert r_i.type == "I-C"
    assert r.measures["fit_r2"] < 0.8 and r.criteria["fit"]
    assert not _classify(*_pair(0.22, 0.23, v_u), max_subevents=2).criteria["subevents"]
    assert _classify(*_pair(0.22, 0.23), min_fit_r2=1.01).criteria["fit"]


def test_pair_restart_and_creep_criteria():
    def precursor(t):
        return _bump(t, 15.0, 2.0, 0.02) + _bump(t, 25.0, PDUR, 0.06)

    r = _classify(*_pair(0.22, 0.23, precursor), main="largest")
    assert r.criteria["restart"] and r.measures["n_restarts"] == 1
    assert r.undrained_slip.onset_time > 24 and len(r.undrained_slips) == 2
    assert r.type == "II-C"
    first = _classify(*_pair(0.22, 0.23, precursor))        # default: the first slip (the precursor)
    assert first.undrained_slip.onset_time < 16 and first.criteria["restart"]

    def creep(t):
        return np.where((t > 10) & (t < 20), PV, 0.0) + _bump(t, 25.0, PDUR, 0.06)

    rc = _classify(*_pair(0.22, 0.23, creep))
    assert rc.criteria["creep"] and not rc.criteria["restart"]
    assert abs(rc.measures["creep_time"] - 10.0) < 0.05
    assert _classify(*_pair(0.22, 0.23, creep), creep_fraction=2.0).type == "II"


def test_campaign_summary_counts_and_ratios():
    def sub(t):
        dip = 1 - 0.7 * np.exp(-(((t - 25.0 - PDUR * 0.6) / 0.4) ** 2))
        return _bump(t, 25.0, PDUR * 1.2, 0.06) * dip

    results = [
        _classify(*_pair(0.22, 0.21)),
        _classify(*_pair(0.22, 0.23)),
        _classify(*_pair(0.22, 0.24)),
        _classify(*_pair(0.22, 0.23, sub)),
        _classify(*_pair(0.22, 0.21, sub)),
    ]
    summary = campaign_summary(results)
    assert summary.n == 5
    assert {k: summary.counts[k] for k in ("I", "II", "I-C", "II-C")} == {
        "I": 1, "II": 2, "I-C": 1, "II-C": 1}
    assert summary.n_type_I == 2 and summary.n_type_II == 3
    assert summary.n_complex == 2 and summary.criteria["subevents"] == 2
    pv = summary.ratios["peak_velocity_ratio"]
    assert pv.n == 5 and pv.frac_below_1 == 1.0 and pv.max < 0.61


def test_notched_refit_removes_the_layers_vibration_and_recovers_eq3():
    from gouge_cli.analysis.blockslider import fit_block_slider
    from gouge_cli.analysis.catalog import notched_refit
    from gouge_cli.io.slipcatalog import SlipEntry

    k, m_b, sigma = 1e-6, 24.0, 3e-4
    omega = math.sqrt(k / m_b)
    half = math.pi / omega                                   # Eq. 3's slip duration, 15,390 t0
    f_s = omega / (2.0 * math.pi)
    t = np.arange(-0.6 * half, 1.6 * half, half / 2000.0)
    amplitude = 5e-3
    slip = np.where((t >= 0.0) & (t <= half), amplitude * np.sin(omega * t), 0.0)
    v = slip + 0.25 * amplitude * np.sin(2.0 * math.pi * 30.0 * f_s * t)     # the layer's vibration at 30 f_s
    inside = np.flatnonzero((t >= 0.0) & (t <= half))
    plain = fit_block_slider(t, v, (int(inside[0]), int(inside[-1])), k, m_b, sigma)
    entry = SlipEntry.from_attrs({"number": 1, "onset_time": 0.0, "end_time": half, "duration": half,
                                  "peak_velocity": amplitude})
    nf = notched_refit(t, v, entry, plain, k, m_b, sigma)
    # unfiltered, the vibration (variance 0.25^2 / 2 = 0.031 A^2) is all the residual, against a half sine's
    # 1/2 - 4/pi^2 = 0.095 A^2: R^2 = 1 - 0.031 / (0.095 + 0.031) = 0.75
    assert abs(plain.r2 - 0.75) < 0.02
    assert abs(nf.natural_frequency / (30.0 * f_s) - 1.0) < 0.02
    assert nf.fit.success and nf.fit.r2 > 0.98
    assert abs(nf.fit.half_period / half - 1.0) < 0.01 and abs(nf.fit.amplitude / amplitude - 1.0) < 0.02
    # no diagnostic (None, a NaN in the study table) where there is nothing sound to refit
    import dataclasses
    assert notched_refit(t, v, entry, dataclasses.replace(plain, success=False), k, m_b, sigma) is None
    coarse = slice(None, None, 200)                          # 11 samples inside the slip
    assert notched_refit(t[coarse], v[coarse], entry, plain, k, m_b, sigma) is None
