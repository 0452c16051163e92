"""Campaign figure over many drained/undrained pairs (thesis Sections 4.2-4.3: 9 Type I, 30 Type II)."""

from __future__ import annotations

from pathlib import Path

import numpy as np
from matplotlib.ticker import MaxNLocator

from ..analysis.forkpairs import campaign, ForkPair
from .style import DRAINED, UNDRAINED, new_figure, save  # noqa: F401

_ORDER = ("I", "I-C", "II", "II-C", "tie", "tie-C", "none")
_COLORS = {"I": "#e76f51", "I-C": "#f4a261", "II": UNDRAINED, "II-C": "#7fa7e0", "tie": "0.5",
           "tie-C": "0.7", "none": "0.85"}


def campaign_figure(pairs: list[ForkPair], path: Path, title: str = "") -> Path:
    """Per permeability, never pooled (one colour each, :func:`~gouge_cli.plots.series.branch_colors`).
    Left: pairs per type. Right: histogram of the undrained/drained peak-velocity ratio (the thesis
    finds undrained slips always slower, ratio < 1), with each permeability's median."""
    from .series import branch_colors
    from ..io.layout import perm_text

    groups = campaign(pairs).groups
    colors = branch_colors([g.permeability for g in groups])
    fig, (ax1, ax2) = new_figure("campaign", 1, 2)
    width = 0.8 / max(len(groups), 1)
    x = np.arange(len(_ORDER))
    top = 1
    any_ratio = False
    for i, g in enumerate(groups):
        perm, c = g.permeability, g.pairs
        regimes = ", ".join(g.regimes)
        label = (f"κ_c = {perm_text(perm)} d² ({regimes}): {c.n} pair{'s' if c.n != 1 else ''}, "
                 f"{c.n_type_I} Type I, {c.n_type_II} Type II, {c.n_complex} complex")
        counts = [c.counts.get(k, 0) for k in _ORDER]
        top = max(top, *counts)
        bars = ax1.bar(x - 0.4 + width * (i + 0.5), counts, width, color=colors[perm], edgecolor="0.3", lw=0.6,
                       label=label)
        ax1.bar_label(bars, fontsize=7)
        ratios = np.array([p.result.peak_velocity_ratio for p in pairs if float(p.permeability) == perm],
                          dtype=float)
        ratios = ratios[np.isfinite(ratios)]
        if ratios.size:
            any_ratio = True
            ax2.hist(ratios, bins=max(5, min(30, ratios.size)), histtype="step", lw=1.6, color=colors[perm],
                     label=f"κ_c = {perm_text(perm)} d²")
            ax2.axvline(float(np.median(ratios)), color=colors[perm], lw=1.0, ls=":",
                        label=f"median {np.median(ratios):.3g}")
    ax1.set_xticks(x, _ORDER)
    ax1.set_xlabel("pair type (I: undrained weaker, II: stronger; -C: complex)")
    ax1.set_ylabel("number of pairs")
    ax1.set_ylim(0, top * 1.35)
    ax1.grid(True, axis="y", color="0.9")
    ax1.legend(fontsize=7, frameon=False, loc="upper right")
    if any_ratio:
        ax2.axvline(1.0, color=DRAINED, lw=1.0, ls="--", label="drained = undrained")
        ax2.legend(fontsize=7, frameon=False)
    else:
        ax2.text(0.5, 0.5, "no pair with a slip in both branches", transform=ax2.transAxes,
                 ha="center", va="center", color="0.4")
    ax2.set_xlabel("peak velocity ratio  v_undrained / v_drained")
    ax2.set_ylabel("number of pairs")
    ax2.grid(True, color="0.9")
    for ax in (ax1, ax2):
        ax.yaxis.set_major_locator(MaxNLocator(integer=True))
    fig.suptitle((title + "\n" if title else "") + "Pair types and undrained/drained peak-velocity ratios, "
                 "each permeability on its own (never pooled)", fontsize=10)
    fig.subplots_adjust(left=0.07, right=0.98, top=0.84, bottom=0.14, wspace=0.25)
    return save(fig, path)
