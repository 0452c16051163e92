"""The mechanism's analysis (analysis.mechanism, the pair columns of analysis.forkpairs): the
drained layer's pressure response against a finite-difference solution of the diffusion equation,
the sign test and the collapse on constructed pairs, and the per-pair quantities on series with
known answers."""

from __future__ import annotations

import math
from types import SimpleNamespace

import numpy as np
import pytest

from gouge_cli.analysis.forkpairs import dilation_before, pressure_before, slip_deborah
from gouge_cli.analysis.mechanism import collapse_point, layer_response, mechanism_rows, sign_outcome


def _diffusion_mean(x: float, n: int = 200) -> float:
    """Mean of P(z, t_w) / (s t_w) for P_t = D P_zz + s on -l < z < l, P(+-l) = 0, P(0) = 0, by
    Crank-Nicolson on n cells (units: l = 1, t_w = 1, so D = 1 / x)."""
    D, dz = 1.0 / x, 2.0 / n
    steps = max(400, int(40 * D))
    dt = 1.0 / steps
    r = D * dt / dz**2
    m = n - 1                                   # interior nodes
    lap = (np.diag(-2.0 * np.ones(m)) + np.diag(np.ones(m - 1), 1) + np.diag(np.ones(m - 1), -1))
    A = np.eye(m) - 0.5 * r * lap
    B = np.eye(m) + 0.5 * r * lap
    P = np.zeros(m)
    Ainv_B, Ainv = np.linalg.solve(A, B), np.linalg.solve(A, np.eye(m))
    for _ in range(steps):
        P = Ainv_B @ P + Ainv @ (dt * np.ones(m))
    full = np.concatenate([[0.0], P, [0.0]])
    return float(dz * (full.sum() - 0.5 * (full[0] + full[-1])) / 2.0)     # trapezoid rule over 2 l


@pytest.mark.parametrize("x", [0.05, 0.3, 1.0, 3.0, 20.0])
def test_layer_response_is_the_diffusion_equation(x):
    """The mode sum against Crank-Nicolson on 200 cells: within 1 % (the FD error is ~0.1 %)."""
    assert layer_response(x) == pytest.approx(_diffusion_mean(x), rel=1e-2)


def test_layer_response_limits():
    assert layer_response(1e-3) == pytest.approx(1e-3 / 3, rel=1e-6)       # drains as it builds: x/3
    assert layer_response(1e6) == pytest.approx(1.0, abs=2e-3)               # undrained
    ys = layer_response(np.logspace(-2, 3, 30))
    assert np.all(np.diff(ys) > 0)


def _pair(eps, kind, diff=None, **extra):
    return {"drained_dilation": eps, "base_type": kind, "permeability": 1e-5,
            "strength_difference": diff if diff is not None else (0.01 if kind == "II" else -0.01), **extra}


def test_sign_outcome():
    assert sign_outcome(_pair(1e-4, "II")) == 1.0        # dilatant hardening
    assert sign_outcome(_pair(-1e-4, "I")) == 1.0        # compaction weakening
    assert sign_outcome(_pair(1e-4, "I")) == 0.0
    assert sign_outcome(_pair(-1e-4, "II")) == 0.0
    for row in (_pair(1e-4, "tie"), _pair(0.0, "II"), _pair(float("nan"), "I"), _pair(1e-4, "none")):
        assert math.isnan(sign_outcome(row))


def test_collapse_point():
    row = _pair(2e-4, "II", diffusion_time=50.0, onset_window=100.0, pressure_peak=-3e-4,
                undrained_pressure=1e-3)
    assert collapse_point(row) == pytest.approx((0.5, 0.3))
    assert all(math.isnan(v) for v in collapse_point({**row, "undrained_pressure": 0.0}))


def test_mechanism_rows_counts_and_seed_level_interval():
    rng = np.random.default_rng(5)
    rows = []
    for seed in ("1", "2", "3"):
        for i in range(10):
            eps = rng.normal(0, 1e-4)
            predicted = i < 8                            # 8 of 10 pairs follow the sign in every seed
            kind = ("II" if eps > 0 else "I") if predicted else ("I" if eps > 0 else "II")
            x = 10 ** rng.uniform(-1, 1)
            rows.append(_pair(eps, kind, seed=seed, diffusion_time=x * 100, onset_window=100.0,
                              undrained_pressure=1e-3, pressure_peak=-1e-3 * layer_response(x) * 1.5))
    rows.append(_pair(1e-4, "II", seed="1", transient=True))       # left out
    out = mechanism_rows(rows)
    pooled = next(r for r in out if r["seed"] == "all")
    assert len(out) == 4 and pooled["n_pairs"] == 30 and pooled["n_signed"] == 30
    assert pooled["predicted"] == pytest.approx(0.8)
    assert pooled["predicted_lo"] < 0.8 < pooled["predicted_hi"]
    assert pooled["predicted_seed_lo"] <= 0.8 <= pooled["predicted_seed_hi"]
    assert pooled["collapse_ratio_median"] == pytest.approx(1.5) and pooled["collapse_within_factor"] == 1.0


def test_pair_quantities_on_known_series():
    t = np.linspace(0.0, 1000.0, 1001)
    h = 10.0 + 1e-3 * t                                     # 10 d thick, 0.5 d thicker at t = 500
    assert dilation_before(t, h, 500.0) == pytest.approx(0.05)
    p = -1e-4 * np.sin(np.pi * t / 1000.0)                  # most negative at t = 500
    assert pressure_before(t, p, 800.0) == pytest.approx(-1e-4)
    assert pressure_before(t, p, 200.0) == pytest.approx(p[200])
    # De: l/D read where the undrained wall is fastest in the slip, times the drained peak speed
    vx = np.where((t > 600) & (t < 700), 2e-3 * np.sin(np.pi * (t - 600) / 100.0), 1e-6)
    de = 40.0 * np.abs(vx)                                   # l/D = 40 t0/d
    slip = SimpleNamespace(onset_time=600.0, end_time=700.0)
    value, l_over_d = slip_deborah(t, de, vx, slip, 5e-3)
    assert l_over_d == pytest.approx(40.0) and value == pytest.approx(0.2)
    assert all(math.isnan(v) for v in slip_deborah(t, de, vx, None, 5e-3))


def test_rate_pressure_is_the_quasi_steady_mean():
    """A layer thinning at a steady rate (compaction): the quasi-steady mean pressure
    (t_D / 3) |h'/h| / (beta phi), positive, read at the time of the pressure peak."""
    from gouge_cli.analysis.forkpairs import rate_pressure
    from gouge_cli.analysis.mechanism import rate_agrees, rate_point

    t = np.arange(0.0, 5000.0, 20.0)
    h = 11.0 - 2e-5 * t                                    # compaction, 2e-5 d / t0
    p = 1e-5 * np.exp(-((t - 3000.0) / 400.0) ** 2)        # the peak at t = 3000
    got = rate_pressure(t, h, p, onset=4000.0, diffusion_time=300.0, beta_phi=36 * 0.16)
    want = 300.0 / 3.0 * 2e-5 / (11.0 - 2e-5 * 3000.0) / (36 * 0.16)
    assert got == pytest.approx(want, rel=1e-9) and got > 0
    row = {"pressure_from_rate": got, "pressure_peak": 1e-5}
    assert rate_point(row) == pytest.approx((got, 1e-5)) and rate_agrees(row)
    assert not rate_agrees({"pressure_from_rate": -got, "pressure_peak": 1e-5})
    assert math.isnan(rate_pressure(t, h, p, onset=float("nan"), diffusion_time=300.0, beta_phi=5.76))
