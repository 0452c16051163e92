"""Spring-block slider: thesis Eqs. 2-3 and the fit of a slip's velocity to Eq. 3.

Per-unit-length form (docs/physics/walls.md): wall mass ``m`` per length, spring
constant ``k`` per length, normal stress ``sigma`` (the normal force N of the
thesis per unit length), friction drop ``dmu = mu_s - mu_d``. With the loading
during slip neglected, Eq. 3 reads

    V_w(t) = dmu * sigma / sqrt(k m) * sin(sqrt(k / m) t),

so a slip lasts half a period, ``pi sqrt(m / k)``, moves ``2 dmu sigma / k``
and recurs every ``2 dmu sigma / (k V_s)``.

Fit bar (:func:`judge_fit`): a fit counts only with ``R^2 >= FIT_MIN_R2`` (0.5) and a fitted
half period within a factor ``FIT_PERIOD_FACTOR`` (2) of the slip's own measured duration;
otherwise ``success`` is False and ``message`` says why (the fitted numbers are kept, but
nothing downstream uses or draws them). The effective block mass of a slip is
``m_eff = k (T_fit / pi)^2`` (T_fit: fitted half period): the mass a rigid block would need
to slip for as long (thesis Section 4.1: constant slip duration is the test of Eq. 3).
A fit that passes the bar but whose half period is not within ``EQ3_PERIOD_FACTOR`` (2) of
``pi sqrt(m_b / k)`` is "inapplicable" (:attr:`BlockSliderFit.verdict`): a sine describes the slip,
but not the wall's block slider of Eq. 3; every output marks it so, and no figure draws it as a fit.
"""

from __future__ import annotations

import math
from dataclasses import asdict, dataclass

import numpy as np
from scipy.optimize import curve_fit

from ..model.timestep import half_period

__all__ = [
    "BlockSliderFit",
    "fit_block_slider",
    "block_slider_duration",
    "block_slider_peak_velocity",
    "block_slider_slip",
    "block_slider_recurrence",
    "block_slider_prediction",
    "simulate_block_slider",
    "judge_fit",
    "FIT_MIN_R2",
    "FIT_PERIOD_FACTOR",
    "EQ3_PERIOD_FACTOR",
]

FIT_MIN_R2 = 0.5
FIT_PERIOD_FACTOR = 2.0
EQ3_PERIOD_FACTOR = 2.0     # Eq. 3 applies when the fitted half period is within this factor of pi sqrt(m_b/k)

_NAN = float("nan")


def block_slider_duration(m: float, k: float) -> float:
    """Slip duration (half period) ``pi sqrt(m / k)``."""
    return half_period(m, k)


def block_slider_peak_velocity(dmu: float, sigma: float, k: float, m: float) -> float:
    """Peak slip velocity ``dmu sigma / sqrt(k m)`` (Eq. 3 amplitude)."""
    return dmu * sigma / math.sqrt(k * m)


def block_slider_slip(dmu: float, sigma: float, k: float) -> float:
    """Slip distance per event ``2 dmu sigma / k``."""
    return 2.0 * dmu * sigma / k


def block_slider_recurrence(dmu: float, sigma: float, k: float, V: float) -> float:
    """Time between events ``2 dmu sigma / (k V)``."""
    return 2.0 * dmu * sigma / (k * V)


def block_slider_prediction(dmu: float, sigma: float, k: float, m: float, V: float) -> dict:
    """All four rigid block-slider predictions as a dict."""
    return {
        "duration": block_slider_duration(m, k),
        "peak_velocity": block_slider_peak_velocity(dmu, sigma, k, m),
        "slip": block_slider_slip(dmu, sigma, k),
        "recurrence": block_slider_recurrence(dmu, sigma, k, V),
    }


@dataclass
class BlockSliderFit:
    """Least-squares fit of ``V(t) = A sin(omega (t - t0)) + baseline`` over one slip."""

    amplitude: float
    omega: float
    t0: float
    half_period: float
    period: float
    predicted_half_period: float
    half_period_ratio: float
    delta_mu: float
    r2: float
    nrms: float
    n_points: int
    success: bool
    message: str = ""
    m_eff: float = float("nan")

    @property
    def reason(self) -> str:
        """Why the fit does not count ("" when it does)."""
        return "" if self.success else (self.message or "failed")

    @property
    def verdict(self) -> str:
        """"holds": the fit passes the bar and its half period is within EQ3_PERIOD_FACTOR of the
        prediction pi sqrt(m_b/k) (so m_eff within EQ3_PERIOD_FACTOR^2 of m_b); "failed": it fails
        the bar (:func:`judge_fit`); "inapplicable": a sine fits, but not with the wall's mass, so
        Eq. 3 does not describe the slip."""
        if not self.success:
            return "failed"
        ratio = self.half_period_ratio
        return "holds" if 1.0 / EQ3_PERIOD_FACTOR <= ratio <= EQ3_PERIOD_FACTOR else "inapplicable"

    @property
    def verdict_reason(self) -> str:
        """Why the fit does not hold ("" when it does), for tables, files and figures."""
        verdict = self.verdict
        if verdict == "failed":
            return f"fit failed: {self.reason}"
        if verdict == "inapplicable":
            return (f"Eq. 3 does not apply: fitted half period {self.half_period_ratio:.3g} x π√(m_b/k) "
                    f"(allowed 1/{EQ3_PERIOD_FACTOR:g} to {EQ3_PERIOD_FACTOR:g}), "
                    f"m_eff = {self.half_period_ratio ** 2:.3g} m_b")
        return ""

    def to_dict(self) -> dict:
        return asdict(self)


def _window(t: np.ndarray, slip) -> tuple[int, int, float, float, float]:
    if isinstance(slip, (tuple, list)):
        i0, i1 = int(slip[0]), int(slip[1])
        return i0, i1, float(t[i0]), float(t[i1] - t[i0]), _NAN
    return (int(slip.onset_index), int(slip.end_index), float(slip.onset_time),
            float(slip.duration), float(slip.peak_velocity))


def fit_block_slider(
    t,
    v_wall,
    slip,
    k: float | None = None,
    m_b: float | None = None,
    sigma: float | None = None,
    *,
    baseline: float = 0.0,
    pad: int = 0,
    min_r2: float = FIT_MIN_R2,
    period_factor: float = FIT_PERIOD_FACTOR,
) -> BlockSliderFit:
    """Fit thesis Eq. 3 to the wall velocity of one slip.

    t, v_wall: arrays of shape (n,). ``slip``: a :class:`~gouge_cli.analysis.slips.Slip`
    (samples ``onset_index .. end_index``) or an ``(i0, i1)`` index pair
    (inclusive), widened by ``pad`` samples each side. ``baseline`` is a fixed
    velocity added to the sine. The initial guess is ``omega = pi / duration``,
    ``t0 = onset``, ``A = peak - baseline``. Reports the fitted half period
    ``pi / omega`` against ``pi sqrt(m_b / k)``, ``delta_mu = A sqrt(k m_b) / sigma``,
    ``R^2 = 1 - SS_res / SS_tot``, ``nrms = rms(residual) / A`` and ``m_eff = k (T_fit/pi)^2``;
    ``success`` is False when the fit fails the bar of :func:`judge_fit`.
    """
    t = np.asarray(t, dtype=float)
    v = np.asarray(v_wall, dtype=float)
    i0, i1, t_on, duration, peak = _window(t, slip)
    i0, i1 = max(i0 - pad, 0), min(i1 + pad, t.size - 1)
    tt, vv = t[i0:i1 + 1], v[i0:i1 + 1] - baseline
    if math.isnan(peak):
        peak = float(vv.max()) + baseline
    predicted = math.pi * math.sqrt(m_b / k) if (k and m_b) else _NAN

    def failed(msg: str) -> BlockSliderFit:
        return BlockSliderFit(_NAN, _NAN, _NAN, _NAN, _NAN, predicted, _NAN, _NAN,
                              _NAN, _NAN, int(tt.size), False, msg)

    if tt.size < 4 or not duration > 0:
        return failed("fewer than 4 samples or zero duration")

    def model(x, A, w, t0):
        return A * np.sin(w * (x - t0))

    p0 = [max(peak - baseline, 1e-300), math.pi / duration, t_on]
    try:
        popt, _ = curve_fit(model, tt, vv, p0=p0,
                            bounds=([0.0, 0.0, -np.inf], [np.inf, np.inf, np.inf]),
                            maxfev=20000)
    except (RuntimeError, ValueError) as exc:
        return failed(str(exc))
    A, w, t0 = (float(q) for q in popt)
    res = vv - model(tt, A, w, t0)
    ss_tot = float(np.sum((vv - vv.mean()) ** 2))
    r2 = 1.0 - float(np.sum(res ** 2)) / ss_tot if ss_tot > 0 else _NAN
    nrms = float(np.sqrt(np.mean(res ** 2))) / A if A > 0 else _NAN
    half = math.pi / w if w > 0 else _NAN
    dmu = A * math.sqrt(k * m_b) / sigma if (k and m_b and sigma) else _NAN
    ok, why = judge_fit(r2, half, duration, min_r2=min_r2, period_factor=period_factor)
    return BlockSliderFit(
        amplitude=A, omega=w, t0=t0, half_period=half, period=2.0 * half,
        predicted_half_period=predicted, half_period_ratio=half / predicted,
        delta_mu=dmu, r2=r2, nrms=nrms, n_points=int(tt.size), success=ok, message=why,
        m_eff=k * (half / math.pi) ** 2 if (k and math.isfinite(half)) else _NAN,
    )


def judge_fit(r2: float, half_period: float, duration: float, *, min_r2: float = FIT_MIN_R2,
              period_factor: float = FIT_PERIOD_FACTOR) -> tuple[bool, str]:
    """The fit bar: ``R^2 >= min_r2`` and ``duration / f <= half_period <= f duration``.

    half_period: fitted pi / omega [t0]; duration: the slip's measured duration [t0].
    Returns ``(passes, reason)`` with an empty reason when it passes.
    """
    if not (r2 >= min_r2):
        return False, f"R^2 = {r2:.3g} < {min_r2:g}"
    ratio = half_period / duration if duration > 0 else _NAN
    if not (1.0 / period_factor <= ratio <= period_factor):
        return False, (f"fitted half period {half_period:.4g} t0 is {ratio:.3g} x the slip's duration "
                       f"{duration:.4g} t0 (allowed 1/{period_factor:g} to {period_factor:g})")
    return True, ""


def simulate_block_slider(
    m: float,
    k: float,
    sigma: float,
    mu_s: float,
    mu_d: float,
    V_s: float,
    dt: float,
    t_end: float,
) -> dict[str, np.ndarray]:
    """Rigid block on a spring: ``m x'' = k (V_s t - x) - sigma mu`` (per length).

    Stuck (v = 0) until ``k (V_s t - x) >= sigma mu_s``; then slides with
    ``mu = mu_d`` (velocity Verlet, step ``dt``) until the velocity returns to
    zero. Starts unstretched at rest. Returns arrays of shape (n,) sampled every
    ``dt``: ``t``, ``x_wall``, ``v_wall``, ``a_wall``, ``tau_over_sigma``.
    """
    n = int(round(t_end / dt)) + 1
    t = np.arange(n) * dt
    x = np.zeros(n)
    v = np.zeros(n)
    a = np.zeros(n)
    xs = 0.0
    i = 0
    while i < n - 1:
        j = int(math.ceil((sigma * mu_s / k + xs) / (V_s * dt)))
        j = max(j, i + 1)
        if j >= n:
            x[i + 1:] = xs
            break
        x[i + 1:j + 1] = xs
        i = j
        xi, vi = xs, 0.0
        ai = (k * (V_s * t[i] - xi) - sigma * mu_d) / m
        a[i] = ai
        while i < n - 1:
            xn = xi + vi * dt + 0.5 * ai * dt * dt
            an = (k * (V_s * t[i + 1] - xn) - sigma * mu_d) / m
            vn = vi + 0.5 * (ai + an) * dt
            i += 1
            if vn <= 0.0:
                xs = xn
                x[i], v[i], a[i] = xs, 0.0, 0.0
                break
            x[i], v[i], a[i] = xn, vn, an
            xi, vi, ai = xn, vn, an
        else:
            break
    tau = k * (V_s * t - x) / sigma
    return {"t": t, "x_wall": x, "v_wall": v, "a_wall": a, "tau_over_sigma": tau}
