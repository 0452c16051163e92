"""The regime map: drained/undrained findings against the Deborah number, with the thesis placed.

Four panels over De (log axis, the median ``deborah_max`` of each permeability's undrained
branches, horizontal bars its range): (a) fractions of Type I, Type II and tie (pair definition,
with its tie band); (b) fraction of Type I by the sign of S_u - S_d alone and of complex (-C)
pairs; (c) shares of pairs whose undrained branch is slower and has the smaller stress drop;
(d) medians of the undrained/drained ratios. Pooled points are filled with 95 % intervals (Wilson
for fractions, bootstrap for medians); each seed is a small open marker. The thesis (39 pairs of
Table 3) is a star with its De range and Wilson intervals.
"""

from __future__ import annotations

from pathlib import Path

import matplotlib.pyplot as plt
import numpy as np

from ..analysis.regime import ThesisPoint
from .style import DPI, save

_COLOURS = {"type_I": "#d62728", "type_II": "#1f5fbf", "tie": "0.5", "type_I_sign": "#ff7f0e",
            "complex": "#2ca02c", "slower": "#1f5fbf", "smaller_drop": "#d62728",
            "peak_velocity_ratio": "#1f5fbf", "stress_drop_ratio": "#d62728", "duration_ratio": "#2ca02c"}
_NAMES = {"type_I": "Type I", "type_II": "Type II", "tie": "tie", "type_I_sign": "Type I by sign (no tie band)",
          "complex": "complex (-C)", "slower": "undrained slower (v ratio < 1)",
          "smaller_drop": "undrained smaller drop (Δτ ratio < 1)", "peak_velocity_ratio": "peak velocity",
          "stress_drop_ratio": "stress drop", "duration_ratio": "duration"}
_PANELS = (("(a) pair types", ("type_I", "type_II", "tie"), "fraction of pairs"),
           ("(b) Type I without tie band, and -C", ("type_I_sign", "complex"), "fraction of pairs"),
           ("(c) thesis: undrained always slower, smaller drop", ("slower", "smaller_drop"), "share of pairs"),
           ("(d) medians of undrained / drained", ("peak_velocity_ratio", "stress_drop_ratio", "duration_ratio"),
            "ratio"))


def _series(rows: list[dict], key: str, seed: str):
    pts = sorted((r["deborah_max_median"], r) for r in rows if r["seed"] == seed and np.isfinite(r["deborah_max_median"]))
    de = np.array([p[0] for p in pts])
    rs = [p[1] for p in pts]
    if key in ("peak_velocity_ratio", "stress_drop_ratio", "duration_ratio"):
        mid = np.array([r[f"{key}_median"] for r in rs])
    else:
        mid = np.array([r[key] for r in rs])
    lo = np.array([r[f"{key}_lo"] for r in rs])
    hi = np.array([r[f"{key}_hi"] for r in rs])
    return de, mid, lo, hi, rs


def regime_figure(rows: list[dict], thesis: ThesisPoint | None, path: Path, title: str = "") -> Path:
    """Write the four-panel regime map of :func:`~gouge_cli.analysis.regime.regime_rows` rows."""
    fig, axes = plt.subplots(2, 2, figsize=(11.0, 8.6), dpi=DPI, sharex=True)
    seeds = sorted({r["seed"] for r in rows if r["seed"] != "all"})
    for ax, (name, keys, ylabel) in zip(axes.flat, _PANELS):
        for j, key in enumerate(keys):
            c = _COLOURS[key]
            de, mid, lo, hi, rs = _series(rows, key, "all")
            if de.size:
                shift = 1.0 + 0.04 * (j - (len(keys) - 1) / 2)     # keep overlapping bars apart
                xerr = np.array([[d - r["deborah_max_min"] for d, r in zip(de, rs)],
                                 [r["deborah_max_max"] - d for d, r in zip(de, rs)]])
                ax.errorbar(de * shift, mid, yerr=[np.clip(mid - lo, 0, None), np.clip(hi - mid, 0, None)],
                            xerr=xerr if j == 0 else None, fmt="o-", color=c, ms=5, lw=1.2,
                            capsize=3, label=f"{_NAMES[key]} (pooled, 95 % CI)")
            for seed in seeds:
                de_s, mid_s, *_ = _series(rows, key, seed)
                if de_s.size:
                    ax.plot(de_s, mid_s, "o", mfc="none", color=c, ms=4, alpha=0.6, lw=0)
            if thesis is not None and key in thesis.fractions:
                f, flo, fhi = thesis.fractions[key]
                ax.errorbar([thesis.deborah], [f], yerr=[[f - flo], [fhi - f]],
                            xerr=[[thesis.deborah - thesis.deborah_lo], [thesis.deborah_hi - thesis.deborah]],
                            fmt="*", color=c, ms=13, mec="k", mew=0.6, capsize=3, alpha=0.9)
        if keys[0] in ("peak_velocity_ratio",):
            ax.axhline(1.0, color="0.3", lw=0.8, ls="--")
        else:
            ax.set_ylim(-0.03, 1.03)
        ax.set_xscale("log")
        ax.set_title(name, fontsize=10, loc="left")
        ax.set_ylabel(ylabel)
        ax.grid(True, which="both", color="0.9", lw=0.6)
        ax.legend(fontsize=7, loc="best")
    for ax in axes[1]:
        ax.set_xlabel("De = l u₀ / D, undrained branch, largest in the slip")
    note = ("open markers: single seeds; ★: the thesis (Table 3, 39 pairs; De from its own parameters, "
            "bars: its range)" if thesis is not None else "open markers: single seeds")
    fig.suptitle((title + "\n" if title else "") + note, fontsize=9)
    fig.tight_layout(rect=(0, 0, 1, 0.95))
    return save(fig, path, {"Title": title or "regime map",
                            "Description": "pair fractions and ratio medians against the Deborah number"})
