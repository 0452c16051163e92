"""Campaign figures: the phase diagram (fraction of -C and of Type II pairs over two swept
parameters, thesis future work A), slip statistics against each swept parameter, and the pair
figure of :mod:`.campaign` once per permeability (pairs at different permeabilities are never
pooled in one histogram)."""

from __future__ import annotations

import math
from pathlib import Path

import matplotlib.pyplot as plt
import numpy as np

from ..io.layout import branch_name, perm_text
from .campaign import campaign_figure
from .style import DPI, save

_STATS = (("stress_drop", "Δτ/σ"), ("peak_velocity_over_Vs", "v_peak / V_s"), ("duration", "duration / t₀"),
          ("recurrence", "recurrence / t₀"))


def _label(key: str | None) -> str:
    return {"permeability": "κ_c of the undrained branch / d²", None: ""}.get(key, key)


def phase_diagram_figure(cells: list[dict], x: str, y: str | None, path: Path, title: str = "") -> Path:
    """Two panels over the (x, y) cells of :func:`~gouge_cli.analysis.campaign_table.phase_cells`:
    fraction of complex (-C) pairs and fraction of Type II pairs, each cell labelled with its
    fraction, its seed-level 95 % interval and the pairs and seeds behind it (grey: no classified
    pair)."""
    xs = sorted({c["x"] for c in cells})
    ys = sorted({c["y"] for c in cells}, key=lambda v: (v is None, v))
    fig, axes = plt.subplots(1, 2, figsize=(10.0, 4.4), dpi=DPI)
    for ax, key, name in ((axes[0], "frac_complex", "fraction complex (-C)"),
                          (axes[1], "frac_type_II", "fraction Type II")):
        grid = np.full((len(ys), len(xs)), np.nan)
        for c in cells:
            grid[ys.index(c["y"]), xs.index(c["x"])] = c[key]
        cmap = plt.get_cmap("viridis").with_extremes(bad="0.85")
        image = ax.imshow(np.ma.masked_invalid(grid), origin="lower", cmap=cmap, vmin=0, vmax=1, aspect="auto")
        for c in cells:
            i, j = ys.index(c["y"]), xs.index(c["x"])
            frac = c[key]
            lo, hi = c.get(f"{key}_lo", math.nan), c.get(f"{key}_hi", math.nan)
            text = ("–" if not math.isfinite(frac) else f"{frac:.2f}"
                    + (f" [{lo:.2f}, {hi:.2f}]" if math.isfinite(lo) and math.isfinite(hi) else ""))
            text += f"\n{c['n_pairs']} pairs, {c.get('n_seeds', '?')} seeds"
            ax.text(j, i, text, ha="center", va="center", fontsize=9,
                    color="white" if math.isfinite(frac) and frac < 0.6 else "black")
        ax.set_xticks(range(len(xs)), [f"{v:g}" for v in xs])
        ax.set_yticks(range(len(ys)), ["" if v is None else f"{v:g}" for v in ys])
        ax.set_xlabel(_label(x))
        ax.set_ylabel(_label(y))
        ax.set_title(name, fontsize=10)
        fig.colorbar(image, ax=ax, fraction=0.05)
    fig.suptitle((title + ": " if title else "") + f"{sum(c['n_pairs'] for c in cells)} classified pairs",
                 fontsize=11)
    fig.subplots_adjust(left=0.1, right=0.97, top=0.86, bottom=0.14, wspace=0.35)
    return save(fig, path)


def sweep_figure(run_rows: list[dict], keys: list[str], path: Path, title: str = "") -> Path:
    """Slip statistics (mean ± std over each run's slips) against each swept key (one row of
    panels per key); runs that share the other swept values are joined by a line (seeds: one
    marker each)."""
    fig, axes = plt.subplots(len(keys), len(_STATS), figsize=(3.2 * len(_STATS), 2.8 * len(keys)),
                             dpi=DPI, squeeze=False)
    for i, key in enumerate(keys):
        others = [k for k in keys if k != key]
        groups: dict[tuple, list[dict]] = {}
        for r in run_rows:
            groups.setdefault(tuple(r[k] for k in others), []).append(r)
        for j, (stat, name) in enumerate(_STATS):
            ax = axes[i, j]
            for g, (label, members) in enumerate(sorted(groups.items())):
                color = plt.get_cmap("tab10")(g % 10)
                xv = np.array([float(r[key]) for r in members])
                mean = np.array([float(r[f"{stat}_mean"]) for r in members])
                std = np.array([float(r[f"{stat}_std"]) for r in members])
                ax.errorbar(xv, mean, yerr=std, fmt="o", ms=4, color=color, capsize=2,
                            label=", ".join(f"{k.rsplit('.', 1)[-1]} {v:g}" for k, v in zip(others, label)) or None)
                order = np.unique(xv)
                line = [np.nanmean(mean[xv == v]) if np.isfinite(mean[xv == v]).any() else np.nan for v in order]
                ax.plot(order, line, "-", color=color, lw=1)
            values = np.unique([float(r[key]) for r in run_rows])
            if values.size and values.min() > 0 and values.max() / values.min() > 20:
                ax.set_xscale("log")
            ax.set_xticks(values, [f"{v:g}" for v in values])
            ax.minorticks_off()
            ax.set_xlabel(key, fontsize=9)
            ax.set_ylabel(name, fontsize=9)
            ax.grid(True, color="0.9")
            ax.tick_params(labelsize=8)
        if others:
            axes[i, 0].legend(fontsize=7, frameon=False)
    fig.suptitle((title + ": " if title else "") + "slip statistics per run (mean ± std over its slips)",
                 fontsize=11)
    fig.tight_layout(rect=(0, 0, 1, 0.95))
    return save(fig, path)


def pair_histograms(pairs_by_perm: dict, folder: Path) -> list[Path]:
    """:func:`~gouge_cli.plots.campaign.campaign_figure` for each permeability on its own."""
    return [campaign_figure(pairs, Path(folder) / f"pairs_{branch_name(perm)}.png", title=f"κ_c = {perm_text(perm)} d²")
            for perm, pairs in sorted(pairs_by_perm.items())]
