"""The loading cycle against the normal stress (:mod:`gouge_cli.analysis.recurrence`): each run's
mean stress drop and recurrence, the recurrence the spring's reloading predicts, and their ratio,
over sigma; runs that do not stick-slip are drawn as such (a cross at the panel's foot), never
dropped."""

from __future__ import annotations

from pathlib import Path

import matplotlib.pyplot as plt
import numpy as np
from matplotlib.transforms import blended_transform_factory

from ..analysis.recurrence import MIN_SLIPS, RunCycle, SigmaCycle
from .style import DPI, save

_PANELS = (("stress_drop", "mean stress drop  Δτ/σ", False),
           ("recurrence", "mean recurrence  / t₀  (○ measured, □ drop σ / (k V))", True),
           ("ratio", "recurrence / (drop σ / (k V))", False))


def recurrence_figure(runs: list[RunCycle], cycles: list[SigmaCycle], path: Path, title: str = "") -> Path:
    """Three panels against sigma (log): the runs' mean drops, their mean recurrences beside the
    reloading time drop sigma / (k V) (squares), and the measured / predicted ratio (1: the layer
    sticks rigidly between slips). Dots: one run (seed); filled diamonds: the mean over the
    stick-slipping seeds with its Student-t 95 % interval; crosses at a panel's foot: runs that
    did not stick-slip (0 slips: steady sliding; 1 slip: no recurrence), labelled with their count."""
    fig, axes = plt.subplots(1, 3, figsize=(15.0, 4.6), dpi=DPI)
    sigmas = [c.sigma for c in cycles]
    for ax, (name, label, log) in zip(axes, _PANELS):
        foot = blended_transform_factory(ax.transData, ax.transAxes)
        slipping = [r for r in runs if r.stick_slips]
        ax.plot([r.sigma for r in slipping], [getattr(r, name) for r in slipping], "o", ms=5, mfc="none",
                color="#1f5fbf", label="one run (seed)")
        if name == "recurrence":
            ax.plot([r.sigma * 1.06 for r in slipping], [r.predicted for r in slipping], "s", ms=4, mfc="none",
                    color="0.4", label="drop σ / (k V), per run")
        labelled = set()
        for c in cycles:
            e = getattr(c, name)
            if np.isfinite(e.value):
                yerr = ([[e.value - e.seed_lo], [e.seed_hi - e.value]] if np.isfinite(e.seed_lo) else None)
                ax.errorbar([c.sigma * 0.94], [e.value], yerr=yerr, fmt="D", color="k", ms=6, capsize=3,
                            label=None if "mean" in labelled else "mean over seeds, 95 % (t)")
                labelled.add("mean")
            if c.n_runs > c.n_stick_slip:
                ax.plot([c.sigma], [0.04], "x", ms=10, mew=2, color="#d62728", transform=foot, clip_on=False,
                        label=None if "still" in labelled else "no stick-slip (0 slips: steady; 1: no recurrence)")
                labelled.add("still")
                ax.annotate(f"{c.n_steady} steady, {c.n_one_slip} one slip", (c.sigma, 0.08), xycoords=foot,
                            ha="center", fontsize=7, color="#d62728")
            ax.annotate(f"{c.n_stick_slip}/{c.n_runs} stick-slip", (c.sigma, 0.96), xycoords=foot, ha="center",
                        va="top", fontsize=7)
        if name == "ratio":
            ax.axhline(1.0, color="0.3", lw=0.8, ls="--")
        ax.set_xscale("log")
        if log and any(getattr(r, name) > 0 for r in slipping):
            ax.set_yscale("log")        # (not where no run stick-slips: nothing to place on it)
        if sigmas:
            ax.set_xlim(min(sigmas) / 1.8, max(sigmas) * 1.8)
            ax.set_xticks(sigmas, [f"{s:g}" for s in sigmas])
            ax.minorticks_off()
        ax.set_xlabel("normal stress σ / E")
        ax.set_title(label, fontsize=9, loc="left")
        ax.grid(True, which="both", color="0.92", lw=0.6)
        ax.legend(fontsize=6.5, loc="center right")
    fig.suptitle((title + ": " if title else "") + f"the loading cycle against σ (stick-slip: ≥ {MIN_SLIPS} slips; "
                 "k per unit wall length, so the wall's length cancels)", fontsize=10)
    fig.tight_layout(rect=(0, 0, 1, 0.94))
    return save(fig, path, {"Title": title or "recurrence against sigma",
                            "Description": "stress drop, recurrence and recurrence / (drop sigma / (k V)) per run "
                                           "and per sigma with seed-level intervals; runs without stick-slip marked"})
