"""Campaign figures: the phase diagram (fraction of -C and of Type II pairs over two swept
parameters, thesis future work A), slip statistics against each swept parameter, and the pair
figure of :mod:`.campaign` once per permeability (pairs at different permeabilities are never
pooled in one histogram)."""

from __future__ import annotations

import math
from pathlib import Path

import matplotlib.pyplot as plt
import numpy as np

from ..analysis.regime import ThesisPoint
from ..io.layout import branch_name, perm_text
from .campaign import campaign_figure
from .style import DPI, save

_STATS = (("stress_drop", "Δτ/σ"), ("peak_velocity_over_Vs", "v_peak / V_s"), ("duration", "duration / t₀"),
          ("recurrence", "recurrence / t₀"))


def _label(key: str | None) -> str:
    return {"permeability": "κ_c of the undrained branch / d²", None: ""}.get(key, key)


_PHASE_KEYS = (("frac_complex", "complex", "fraction complex (-C)"), ("frac_type_II", "type_II", "fraction Type II"))


def _cell_text(c: dict, key: str) -> str:
    """A cell's fraction, its seed-level interval, and the pairs and seeds behind it."""
    frac = c[key]
    lo, hi = c.get(f"{key}_lo", math.nan), c.get(f"{key}_hi", math.nan)
    text = ("–" if not math.isfinite(frac) else f"{frac:.2f}"
            + (f" [{lo:.2f}, {hi:.2f}]s" if math.isfinite(lo) and math.isfinite(hi) else ""))
    return text + f"\n{c['n_pairs']} pairs, {c.get('n_seeds', '?')} seeds"


def _grid_position(values: list, v: float | None) -> float | None:
    """Where ``v`` falls on a categorical axis of sorted positive ``values`` (log-interpolated
    between ticks); None outside them or where the axis is not numeric."""
    if v is None or not values or any(x is None or not x > 0 for x in values) or not values[0] <= v <= values[-1]:
        return None
    if len(values) == 1:
        return 0.0
    return float(np.interp(math.log(v), [math.log(x) for x in values], range(len(values))))


def _thesis_label(thesis: ThesisPoint, fraction: str) -> str:
    f, lo, hi = thesis.fractions[fraction]
    return (f"★ thesis (κ_c {thesis.kappa_c:g} d², σ {thesis.normal_stress:g} E): {f:.2f} [{lo:.2f}, {hi:.2f}] "
            f"(Wilson, {thesis.n_pairs} pairs)")


def phase_diagram_figure(cells: list[dict], x: str, y: str | None, path: Path, title: str = "",
                         thesis: ThesisPoint | None = None) -> Path:
    """Panels over the (x, y) cells of :func:`~gouge_cli.analysis.campaign_table.phase_cells`:
    fraction of complex (-C) pairs and fraction of Type II pairs, each cell labelled with its
    fraction, its seed-level 95 % interval (s) and the pairs and seeds behind it (grey: no
    classified pair). Where the cells carry a measured De, a second row places the same cells at
    (their median De, y), with the De range as a bar: the map by measured De rather than kappa_c.
    ``thesis``: its point (a star) where x and y are axes it has a value on (kappa_c, sigma), and
    at its De on the second row, with its Table 3 fraction and Wilson interval in the legend."""
    xs = sorted({c["x"] for c in cells})
    ys = sorted({c["y"] for c in cells}, key=lambda v: (v is None, v))
    by_de = [c for c in cells if math.isfinite(c.get("de_median", math.nan))]
    rows = 2 if by_de else 1
    fig, axes = plt.subplots(rows, 2, figsize=(10.5, 4.4 * rows), dpi=DPI, squeeze=False)
    cmap = plt.get_cmap("viridis").with_extremes(bad="0.85")
    star = None
    if thesis is not None:
        tx, ty = _grid_position(xs, thesis.at(x)), (0.0 if y is None else _grid_position(ys, thesis.at(y)))
        star = (tx, ty) if tx is not None and ty is not None else None
    for col, (key, fraction, name) in enumerate(_PHASE_KEYS):
        ax = axes[0, col]
        grid = np.full((len(ys), len(xs)), np.nan)
        for c in cells:
            grid[ys.index(c["y"]), xs.index(c["x"])] = c[key]
        image = ax.imshow(np.ma.masked_invalid(grid), origin="lower", cmap=cmap, vmin=0, vmax=1, aspect="auto")
        for c in cells:
            frac = c[key]
            ax.text(xs.index(c["x"]), ys.index(c["y"]), _cell_text(c, key), ha="center", va="center", fontsize=8,
                    color="white" if math.isfinite(frac) and frac < 0.6 else "black")
        if star is not None:
            ax.plot([star[0]], [star[1] + 0.32], "*", ms=15, color=cmap(thesis.fractions[fraction][0]), mec="r", mew=1.2,
                    label=_thesis_label(thesis, fraction))
            ax.legend(fontsize=6.5, loc="upper center", bbox_to_anchor=(0.5, -0.14), frameon=False)
        ax.set_xticks(range(len(xs)), [f"{v:g}" for v in xs])
        ax.set_yticks(range(len(ys)), ["" if v is None else f"{v:g}" for v in ys])
        ax.set_xlabel(_label(x))
        ax.set_ylabel(_label(y))
        ax.set_title(name, fontsize=10)
        fig.colorbar(image, ax=ax, fraction=0.05)
        if by_de:
            _by_deborah(axes[1, col], by_de, key, fraction, y, thesis, cmap)
    fig.suptitle((title + ": " if title else "") + f"{sum(c['n_pairs'] for c in cells)} classified pairs; "
                 "[ ]s: seed-level 95 % intervals", fontsize=11)
    fig.tight_layout(rect=(0, 0, 1, 0.95))
    return save(fig, path, {"Title": title or "phase diagram",
                            "Description": "fractions of -C and Type II pairs per cell with seed-level intervals"
                                           + ("; the thesis placed" if star is not None else "")})


def _by_deborah(ax, cells: list[dict], key: str, fraction: str, y: str | None, thesis: ThesisPoint | None, cmap):
    """The cells at (measured De, y): colour the fraction, the De range a bar, the text as above."""
    yv = [0.0 if c["y"] is None else c["y"] for c in cells]
    for c, v in zip(cells, yv):
        ax.plot([c["de_min"], c["de_max"]], [v, v], color="0.6", lw=1.0, zorder=1)
        ax.scatter([c["de_median"]], [v], s=160, c=[c[key]], cmap=cmap, vmin=0, vmax=1, edgecolors="k", zorder=2,
                   plotnonfinite=True)
        same_row = sorted(d["de_median"] for d, w in zip(cells, yv) if w == v)
        up = same_row.index(c["de_median"]) % 2 == 0           # (neighbours' labels above and below)
        lo, hi = c.get(f"{key}_lo", math.nan), c.get(f"{key}_hi", math.nan)
        text = "–" if not math.isfinite(c[key]) else f"{c[key]:.2f}" + (
            f"\n[{lo:.2f}, {hi:.2f}]s" if math.isfinite(lo) and math.isfinite(hi) else "")
        ax.annotate(text + f"\nκ_c {c['x']:g}", (c["de_median"], v), textcoords="offset points",
                    xytext=(0, 10 if up else -10), ha="center", va="bottom" if up else "top", fontsize=6)
    ty = 0.0 if y is None else (thesis.at(y) if thesis is not None else None)
    if thesis is not None and ty is not None:
        f = thesis.fractions[fraction][0]
        ax.errorbar([thesis.deborah], [ty], xerr=[[thesis.deborah - thesis.deborah_lo], [thesis.deborah_hi - thesis.deborah]],
                    fmt="*", ms=15, color="r", mfc=cmap(f), mec="r", capsize=2, lw=0.8, zorder=3,
                    label=_thesis_label(thesis, fraction) + "; bar: its De range")
        ax.legend(fontsize=6.5, loc="upper center", bbox_to_anchor=(0.5, -0.16), frameon=False)
    ax.set_xscale("log")
    if y is not None and all(v > 0 for v in yv):
        ax.set_yscale("log")
        ax.set_ylim(min(yv) / 2.0, max(yv) * 2.0)            # (room for the labels above and below)
        ax.set_yticks(sorted(set(yv)), [f"{v:g}" for v in sorted(set(yv))])
        ax.minorticks_off()
    ax.set_xlabel("measured De (median over the cell's pairs; bar: range)"
                  + (" of the slip" if all(c.get("de_column") == "deborah_drained" for c in cells) else ""))
    ax.set_ylabel(_label(y))
    ax.grid(True, which="both", color="0.92", lw=0.6)


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
