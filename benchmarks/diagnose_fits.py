"""Why do a run's drained slips fail the Eq. 3 fit targets? One row per non-transient slip and a
figure of the worst cases (the study scene's diagnosis: docs/validation.md, "The study scene").

    .venv/bin/python benchmarks/diagnose_fits.py RUN_DIR [FIGURE.png] [--worst 8]

Per slip: stress drop, peak [V_s], measured duration (1.5 V_s crossings) over the median, the
Eq. 3 fit exactly as `gouge study` makes it (R^2, fitted half period T_fit, m_eff / m_b =
k (T_fit/pi)^2 / m_b, fitted start minus detected onset), the ratio of the rise (onset to peak)
to the fall (peak to end), the share of the fit residual's power in three bands of the Eq. 3
frequency f_s = sqrt(k/m_b)/2pi -- "shape" (< 12 f_s: the velocity is not a half sine, i.e.
mu_d is not constant), "vibration" (12-40 f_s: the layer's natural vibration, which thesis
Sec. 4.1 calls an artifact Eq. 3 does not describe), "noise" (above) -- and R^2 of the same
fit refitted after a notch (q = 3) at the residual's spectral peak above 12 f_s (the layer's
natural frequency), i.e. with that vibration removed; and Eq. 7's mu_d(t) (notch-filtered, as
`gouge plot`) averaged over tenths of the slip: mu_d_drop = mu_s minus its mean over the central
60 % (the Delta mu of Eq. 3), mu_d_spread = the range of those six means (how far mu_d is from the
constant Eq. 3 assumes). Diagnosis only: the study's statistics
use the unfiltered fit.
"""

from __future__ import annotations

import math
import sys

import numpy as np
from scipy import signal

from gouge_cli.analysis.catalog import (NOTCH_ABOVE, NOTCH_PAD, fit_slip, fit_slip_notched, read_catalog,
                                       slip_friction, slip_window)
from gouge_cli.analysis.study import DURATION_TOL, GOOD_R2, transient_slips, within_median
from gouge_cli.io.runreader import RunReader

BANDS = (("shape", 0.0, NOTCH_ABOVE), ("vibration", NOTCH_ABOVE, 40.0), ("noise", 40.0, math.inf))


def diagnose(reader: RunReader) -> list[dict]:
    info = reader.info
    f_s = math.sqrt(info.k / info.m_b) / (2.0 * math.pi)
    catalog = read_catalog(reader)
    transient = transient_slips(catalog)
    rows = []
    for e in catalog:
        if e.number in transient:
            continue
        fit = fit_slip(reader, e)
        nf = fit_slip_notched(reader, e, fit)
        j0, j1 = slip_window(reader, e, pad=NOTCH_PAD)[2:]
        s = reader.series(["time", "wall_vx", "tau_over_sigma"], j0, j1)
        t, v = s["time"], s["wall_vx"]
        inside = (t >= e.onset_time) & (t <= e.end_time)
        res = v[inside] - fit.amplitude * np.sin(fit.omega * (t[inside] - fit.t0))
        fs = 1.0 / float(np.mean(np.diff(t)))
        f, p = signal.periodogram(res, fs=fs, nfft=max(res.size, 65536), detrend=False)
        total = float(p.sum()) or 1.0
        share = {name: float(p[(f >= lo * f_s) & (f < hi * f_s)].sum()) / total for name, lo, hi in BANDS}
        f_nat, v_notched, r2_notched = (nf.natural_frequency, nf.notched, nf.fit.r2) if nf else (math.nan, v, math.nan)
        fr = slip_friction(reader, e, notch=True, pad=0.0)
        mu = fr.filtered if fr.filtered is not None else fr.friction
        phase = (fr.t - fr.onset_time) / (fr.end_time - fr.onset_time)
        tenths = [float(np.mean(mu[(phase >= a) & (phase < a + 0.1)])) for a in np.arange(0.2, 0.8, 0.1)]
        rows.append({
            "slip": e.number, "mu_d_drop": fr.mu_s - float(np.mean(tenths)),
            "mu_d_spread": float(np.ptp(tenths)), "stress_drop": e.stress_drop,
            "peak_over_Vs": e.peak_velocity / info.V_s, "duration": e.duration,
            "r2": fit.r2, "fit_ok": fit.success, "T_fit": fit.half_period, "m_eff_over_m_b": fit.m_eff / info.m_b,
            "start_shift": fit.t0 - e.onset_time,
            "rise_over_fall": (e.peak_time - e.onset_time) / (e.end_time - e.peak_time),
            **{f"res_{k}": x for k, x in share.items()}, "f_nat_over_f_s": f_nat / f_s, "r2_notched": r2_notched,
            "t": t - e.onset_time, "v": v / info.V_s, "v_notched": v_notched / info.V_s,
            "tau": s["tau_over_sigma"], "fit_curve": (t[inside] - e.onset_time,
                                                      fit.amplitude * np.sin(fit.omega * (t[inside] - fit.t0)) / info.V_s),
        })
    med = float(np.median([r["duration"] for r in rows])) if rows else math.nan
    for r, ok in zip(rows, within_median([r["duration"] for r in rows])):
        r["duration_over_median"] = r["duration"] / med
        r["duration_within"] = ok
    return rows


def print_table(rows: list[dict]) -> None:
    cols = ("slip", "mu_d_drop", "mu_d_spread", "stress_drop", "peak_over_Vs", "duration_over_median", "r2", "r2_notched", "T_fit",
            "m_eff_over_m_b", "start_shift", "rise_over_fall", "res_shape", "res_vibration", "res_noise",
            "f_nat_over_f_s")
    print(",".join(cols))
    for r in rows:
        print(",".join(f"{r[c]:.4g}" if isinstance(r[c], float) else str(r[c]) for c in cols))
    n = len(rows)
    good = sum(1 for r in rows if r["fit_ok"] and r["r2"] > GOOD_R2)
    good_n = sum(1 for r in rows if r["fit_ok"] and r["r2_notched"] > GOOD_R2)
    within = sum(1 for r in rows if r["duration_within"])
    m = np.array([r["m_eff_over_m_b"] for r in rows if r["fit_ok"]])
    def ratio(sel):
        x = [r["mu_d_spread"] / r["mu_d_drop"] for r in rows if sel(r)]
        return f"{np.median(x):.2f}" if x else "-"
    print(f"# median mu_d_spread / mu_d_drop: slips with R^2 > {GOOD_R2} {ratio(lambda r: r['r2'] > GOOD_R2)}, "
          f"the others {ratio(lambda r: r['r2'] <= GOOD_R2)}, all {ratio(lambda r: True)}")
    share = {k: np.mean([r[f"res_{k}"] for r in rows]) for k, _, _ in BANDS}
    print(f"# {n} non-transient slips: R^2 > {GOOD_R2}: {good} ({good / n:.0%}); with the natural vibration "
          f"notched: {good_n} ({good_n / n:.0%}); durations within {DURATION_TOL:.0%} of the median: "
          f"{within} ({within / n:.0%}); stress drops {min(r['stress_drop'] for r in rows):.3f}-"
          f"{max(r['stress_drop'] for r in rows):.3f}; m_eff/m_b {m.mean():.3g} +- {m.std():.2g}; mean residual power share "
          + ", ".join(f"{k} {x:.0%}" for k, x in share.items()))


def plot_worst(rows: list[dict], path: str, n: int) -> None:
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    worst = sorted(rows, key=lambda r: r["r2"])[:n]
    nc = 4
    nr = math.ceil(len(worst) / nc)
    fig, axs = plt.subplots(nr, nc, figsize=(4.2 * nc, 2.9 * nr), squeeze=False)
    for ax, r in zip(axs.flat, worst):
        ax.plot(r["t"], r["v"], color="0.25", lw=0.6, label="wall velocity")
        ax.plot(r["t"], r["v_notched"], color="tab:green", lw=0.8, label="natural vibration notched")
        ax.plot(*r["fit_curve"], color="tab:red", lw=1.4, label="Eq. 3 fit")
        ax.axvline(0, color="0.6", lw=0.5)
        ax.axvline(r["duration"], color="0.6", lw=0.5)
        ax2 = ax.twinx()
        ax2.plot(r["t"], r["tau"], color="tab:blue", lw=0.5)
        ax2.tick_params(labelsize=6, colors="tab:blue")
        ax.set_title(f"slip {r['slip']}: R² {r['r2']:.2f} (notched {r['r2_notched']:.2f}); drop {r['stress_drop']:.3f}\n"
                     f"duration {r['duration_over_median']:.2f}× median, m_eff {r['m_eff_over_m_b']:.2f} m_b, "
                     f"residual {r['res_shape']:.0%} shape / {r['res_vibration']:.0%} vibration", fontsize=7)
        ax.set_xlabel("t − onset [t0]", fontsize=7)
        ax.set_ylabel("V_w / V_s", fontsize=7)
        ax.tick_params(labelsize=6)
    for ax in list(axs.flat)[len(worst):]:
        ax.axis("off")
    axs.flat[0].legend(fontsize=6, loc="upper right")
    fig.suptitle("worst Eq. 3 fits of the study scene's drained slips (blue: τ/σ, right axis; grey lines: "
                 "detected onset and end at 1.5 V_s)", fontsize=8)
    fig.tight_layout()
    fig.savefig(path, dpi=110)


def main(argv: list[str]) -> None:
    worst = 8
    if "--worst" in argv:
        i = argv.index("--worst")
        worst = int(argv[i + 1])
        argv = argv[:i] + argv[i + 2:]
    with RunReader(argv[0]) as reader:
        rows = diagnose(reader)
        catalog = read_catalog(reader)
        end = reader.series(["time"], reader.info.n_samples - 1)["time"][0] - reader.time_offset()
    print_table(rows)
    print(f"# {len(catalog)} slips ({len(rows)} steady) in {end:.3g} t0 of loading")
    if len(argv) > 1:
        plot_worst(rows, argv[1], worst)


if __name__ == "__main__":
    main(sys.argv[1:])
