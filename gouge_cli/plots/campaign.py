"""Campaign figure over many drained/undrained pairs (thesis Sections 4.2-4.3: 9 Type I, 30 Type II)."""

from __future__ import annotations

from pathlib import Path

import numpy as np
from matplotlib.ticker import MaxNLocator

from ..analysis.forkpairs import campaign, ForkPair
from .style import DRAINED, UNDRAINED, new_figure, save

_ORDER = ("I", "I-C", "II", "II-C", "tie", "tie-C", "none")
_COLORS = {"I": "#e76f51", "I-C": "#f4a261", "II": UNDRAINED, "II-C": "#7fa7e0", "tie": "0.5",
           "tie-C": "0.7", "none": "0.85"}


def campaign_figure(pairs: list[ForkPair], path: Path, title: str = "") -> Path:
    """Left: pairs per type. Right: histogram of the undrained/drained peak-velocity ratio
    (the thesis finds undrained slips always slower, ratio < 1)."""
    summary = campaign(pairs)
    fig, (ax1, ax2) = new_figure("campaign", 1, 2)
    counts = [summary["counts"].get(k, 0) for k in _ORDER]
    bars = ax1.bar(_ORDER, counts, color=[_COLORS[k] for k in _ORDER], edgecolor="0.3", lw=0.6)
    ax1.bar_label(bars, fontsize=8)
    ax1.set_xlabel("pair type (undrained vs drained)")
    ax1.set_ylabel("number of pairs")
    ax1.set_ylim(0, max(counts + [1]) * 1.2)
    ax1.grid(True, axis="y", color="0.9")
    ratios = np.array([p.row["peak_velocity_ratio"] for p in pairs], dtype=float)
    ratios = ratios[np.isfinite(ratios)]
    if ratios.size:
        bins = max(5, min(30, ratios.size))
        ax2.hist(ratios, bins=bins, color=UNDRAINED, alpha=0.8, edgecolor="white")
        ax2.axvline(1.0, color=DRAINED, lw=1.0, ls="--", label="drained = undrained")
        ax2.axvline(float(np.median(ratios)), color="#d62728", lw=1.0,
                    label=f"median {np.median(ratios):.3g}")
        ax2.legend(fontsize=8, frameon=False)
    else:
        ax2.text(0.5, 0.5, "no pair with a slip in both branches", transform=ax2.transAxes,
                 ha="center", va="center", color="0.4")
    ax2.set_xlabel("peak velocity ratio  v_undrained / v_drained")
    ax2.set_ylabel("number of pairs")
    ax2.grid(True, color="0.9")
    for ax in (ax1, ax2):
        ax.yaxis.set_major_locator(MaxNLocator(integer=True))
    n1, n2 = summary["n_type_I"], summary["n_type_II"]
    fig.suptitle((title + ": " if title else "") +
                 f"{summary['n']} pairs, {n1} Type I, {n2} Type II, {summary['n_complex']} complex (-C)",
                 fontsize=11)
    fig.subplots_adjust(left=0.07, right=0.98, top=0.88, bottom=0.14, wspace=0.25)
    return save(fig, path)
