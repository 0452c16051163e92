"""Dynamic friction and shear resistance from the top wall's motion (thesis Eqs. 5-7).

The thesis (Section 5.3) writes the wall's force balance (per unit wall
length, so A = 1 and forces are stresses) as

    Eq. 5:  m_b x'' = sigma mu_s + k V_s t - k x(t) - (sigma - P*(t)) mu_d(t)
    Eq. 6:  mu_d(t) (sigma - P*(t)) = sigma mu_s - k x(t) - m_b a(t)
    Eq. 7:  mu_d(t) = [sigma mu_s - k x(t) - m_b a(t)] / sigma        (drained, P* = 0)

with t and x measured from the slip onset, where the spring force is
``sigma mu_s``, the loading term ``k V_s t`` dropped in Eqs. 6-7, and the
acceleration ``a = (V_w(t + dt) - V_w(t - dt)) / (2 dt)``. Here we keep the
loading term and use the spring force itself, ``tau(t) = k (V_s t - x(t))``
(docs/physics/walls.md; it equals ``sigma mu_s + k V_s t - k x`` from the
onset), so

    R(t) = mu_d(t) (sigma - P*(t)) = tau(t) - m_b a(t)        (Eq. 6)
    mu_d(t) = R(t) / sigma                                     (Eq. 7, drained)

``m_b`` is the wall mass per unit length, ``k`` the spring constant per unit
length, ``sigma`` the normal stress; all dimensionless.
"""

from __future__ import annotations

import math

import numpy as np
from scipy import signal

__all__ = [
    "wall_acceleration",
    "spring_stress",
    "estimate_natural_frequency",
    "notch_filter",
    "shear_resistance",
    "dynamic_friction",
    "effective_pressure",
    "mean_dynamic_friction",
]


def wall_acceleration(t, v_wall=None, x_wall=None, method: str = "velocity") -> np.ndarray:
    """Wall acceleration, shape (n,).

    ``method="velocity"``: centred difference of ``v_wall`` (Eq. 6's
    ``(V(t+dt) - V(t-dt)) / 2dt``; one-sided at the two ends, non-uniform
    spacing allowed). ``method="displacement"``: second difference of
    ``x_wall``; the two end values copy their neighbours.
    """
    t = np.asarray(t, dtype=float)
    if method == "velocity":
        if v_wall is None:
            raise ValueError("method='velocity' needs v_wall")
        return np.gradient(np.asarray(v_wall, dtype=float), t)
    if method == "displacement":
        if x_wall is None:
            raise ValueError("method='displacement' needs x_wall")
        x = np.asarray(x_wall, dtype=float)
        if x.size < 3:
            raise ValueError("need at least 3 samples")
        h1, h2 = np.diff(t)[:-1], np.diff(t)[1:]
        a = np.empty_like(x)
        a[1:-1] = 2.0 * ((x[2:] - x[1:-1]) / h2 - (x[1:-1] - x[:-2]) / h1) / (h1 + h2)
        a[0], a[-1] = a[1], a[-2]
        return a
    raise ValueError(f"unknown method {method!r}: use 'velocity' or 'displacement'")


def spring_stress(t, x_wall, V_s: float, k: float) -> np.ndarray:
    """Spring force per length ``tau = k (V_s t - x_wall)``, shape (n,)."""
    return k * (V_s * np.asarray(t, dtype=float) - np.asarray(x_wall, dtype=float))


def _uniform_fs(t: np.ndarray) -> float:
    dt = np.diff(t)
    if dt.size == 0 or not np.all(dt > 0):
        raise ValueError("t must be strictly increasing with at least 2 samples")
    if np.ptp(dt) > 1e-6 * dt.mean():
        raise ValueError("the notch filter needs a uniform sampling cadence")
    return 1.0 / float(dt.mean())


def estimate_natural_frequency(t, y, f_min: float | None = None,
                               f_max: float | None = None) -> float:
    """Frequency (cycles per time unit) of the largest spectral peak of ``y`` in [f_min, f_max].

    Periodogram of the linearly detrended signal (Hann window, zero-padded to
    at least 65536 points for short windows). ``f_min``
    defaults to ``20 / (t[-1] - t[0])``; pass a value above the slip frequency
    ``sqrt(k / m_b) / 2 pi`` when the series holds whole slips.
    """
    t = np.asarray(t, dtype=float)
    fs = _uniform_fs(t)
    y = np.asarray(y, dtype=float)
    f, pxx = signal.periodogram(y, fs=fs, window="hann", detrend="linear",
                                nfft=max(y.size, 65536))
    lo = 20.0 / (t[-1] - t[0]) if f_min is None else f_min
    hi = fs / 2 if f_max is None else f_max
    sel = (f >= lo) & (f <= hi) & (f > 0) & (f < fs / 2)
    if not np.any(sel):
        raise ValueError(f"no frequencies in [{lo}, {hi}]")
    return float(f[sel][np.argmax(pxx[sel])])


def notch_filter(t, y, freq: float | None = None, q: float = 3.0,
                 f_min: float | None = None, f_max: float | None = None):
    """Zero-phase notch (``scipy.signal.iirnotch`` + ``filtfilt``) at ``freq``.

    ``freq=None`` estimates it with :func:`estimate_natural_frequency` (``f_min``,
    ``f_max``). ``q`` is the quality factor (centre frequency / bandwidth).
    Needs a uniform cadence. Returns ``(filtered y of shape (n,), freq)``.
    """
    t = np.asarray(t, dtype=float)
    y = np.asarray(y, dtype=float)
    fs = _uniform_fs(t)
    if freq is None:
        freq = estimate_natural_frequency(t, y, f_min, f_max)
    if not 0 < freq < fs / 2:
        raise ValueError(f"notch frequency {freq} outside (0, fs/2 = {fs / 2})")
    b, a = signal.iirnotch(freq, q, fs=fs)
    return signal.filtfilt(b, a, y), float(freq)


def shear_resistance(
    t,
    v_wall,
    m_b: float,
    *,
    x_wall=None,
    V_s: float | None = None,
    k: float | None = None,
    tau=None,
    method: str = "velocity",
    notch: float | str | None = None,
    notch_q: float = 3.0,
    notch_fmin: float | None = None,
) -> np.ndarray:
    """Instantaneous shear resistance ``R(t) = mu_d(t) (sigma - P*(t)) = tau - m_b a`` (Eq. 6).

    Spring force per length ``tau`` (shape (n,)) is given directly or computed
    as ``k (V_s t - x_wall)``. ``a`` from :func:`wall_acceleration` (``method``).
    ``notch``: ``None`` (no filter), a frequency, or ``"auto"`` (largest spectral
    peak of R above ``notch_fmin``, default ``5 sqrt(k / m_b) / 2 pi`` when k is
    known) to remove the layer's natural vibration. Returns shape (n,).
    """
    t = np.asarray(t, dtype=float)
    if tau is None:
        if x_wall is None or V_s is None or k is None:
            raise ValueError("give tau, or x_wall with V_s and k")
        tau = spring_stress(t, x_wall, V_s, k)
    tau = np.asarray(tau, dtype=float)
    a = wall_acceleration(t, v_wall=v_wall, x_wall=x_wall, method=method)
    r = tau - m_b * a
    if notch is None:
        return r
    if isinstance(notch, str):
        if notch != "auto":
            raise ValueError("notch must be None, a frequency or 'auto'")
        if notch_fmin is None and k:
            notch_fmin = 5.0 * math.sqrt(k / m_b) / (2.0 * math.pi)
        r, _ = notch_filter(t, r, None, notch_q, f_min=notch_fmin)
        return r
    r, _ = notch_filter(t, r, float(notch), notch_q)
    return r


def dynamic_friction(
    t,
    v_wall,
    m_b: float,
    sigma: float,
    *,
    x_wall=None,
    V_s: float | None = None,
    k: float | None = None,
    tau_over_sigma=None,
    method: str = "velocity",
    notch: float | str | None = None,
    notch_q: float = 3.0,
    notch_fmin: float | None = None,
) -> np.ndarray:
    """Drained dynamic friction ``mu_d(t) = [k (V_s t - x) - m_b a] / sigma`` (Eq. 7), shape (n,).

    Same inputs as :func:`shear_resistance`; ``tau_over_sigma`` (the recorded
    friction series) may replace ``x_wall, V_s, k``. For an undrained run the
    result is ``R / sigma = mu_d (1 - P*/sigma)``.
    """
    tau = None if tau_over_sigma is None else np.asarray(tau_over_sigma, dtype=float) * sigma
    r = shear_resistance(t, v_wall, m_b, x_wall=x_wall, V_s=V_s, k=k, tau=tau,
                         method=method, notch=notch, notch_q=notch_q,
                         notch_fmin=notch_fmin)
    return r / sigma


def effective_pressure(resistance, mu_d, sigma: float) -> np.ndarray:
    """Effective fluid pressure ``P* = sigma - R / mu_d`` from Eq. 6, given a reference mu_d.

    ``mu_d`` may be a scalar (e.g. the drained twin's mean dynamic friction) or
    an array broadcastable to ``resistance``.
    """
    return sigma - np.asarray(resistance, dtype=float) / mu_d


def mean_dynamic_friction(t, mu_d, slip, trim: float = 0.25) -> float:
    """Mean of ``mu_d`` over the central part of a slip.

    Uses samples with ``onset + trim * duration <= t <= end - trim * duration``
    (``slip`` has ``onset_time`` and ``end_time``, or is a ``(t_start, t_end)``
    pair), leaving out the drop from static friction at the start and the
    arrest at the end. NaN if no sample qualifies.
    """
    if not 0 <= trim < 0.5:
        raise ValueError("trim must be in [0, 0.5)")
    if isinstance(slip, (tuple, list)):
        t_on, t_end = float(slip[0]), float(slip[1])
    else:
        t_on, t_end = float(slip.onset_time), float(slip.end_time)
    d = t_end - t_on
    t = np.asarray(t, dtype=float)
    sel = (t >= t_on + trim * d) & (t <= t_end - trim * d)
    if not np.any(sel):
        return float("nan")
    return float(np.mean(np.asarray(mu_d, dtype=float)[sel]))
