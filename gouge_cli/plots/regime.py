"""The regime map: drained/undrained findings against the Deborah number, with the thesis placed,
and the "undrained slower" shares against the onset delay.

:func:`regime_figure`: one panel per quantity (Type I, Type II, tie, Type I by sign, -C, slower,
smaller drop, and the medians of the three undrained/drained ratios) over De (log axis, the median
De of the slips at each permeability, ``analysis.regime.abscissa``: Eq. 4 with the drained twin's
peak wall speed; the grey line its range). At each
permeability: the pooled value (filled) with its seed-level 95 % interval (thick bar: seeds
resampled, then pairs within them) and, just left, its per-pair interval (thin bar: Wilson for
fractions, pair bootstrap for medians); just right, each seed's own value as a dot (a strip plot:
its area grows with the seed's pair count). The thesis (39 pairs of Table 3) is a star with its De
range and Wilson intervals.

:func:`delay_figure`: the peak-velocity and stress-drop ratios of every pair against the
undrained branch's onset delay, and the slower / smaller-drop shares per delay bin
(``analysis.regime.delay_rows``) with both intervals.
"""

from __future__ import annotations

from pathlib import Path

import matplotlib.pyplot as plt
import numpy as np

from ..analysis.regime import COMPARED, GroupCell, ThesisPoint, abscissa
from .style import DPI, save

_COLOURS = {"type_I": "#d62728", "type_II": "#1f5fbf", "tie": "0.5", "type_I_sign": "#ff7f0e",
            "complex": "#2ca02c", "slower": "#1f5fbf", "smaller_drop": "#d62728",
            "peak_velocity_ratio": "#1f5fbf", "stress_drop_ratio": "#d62728", "duration_ratio": "#2ca02c"}
_NAMES = {"type_I": "Type I", "type_II": "Type II", "tie": "tie", "type_I_sign": "Type I by sign (no tie band)",
          "complex": "complex (-C)", "slower": "undrained slower (v ratio < 1)",
          "smaller_drop": "undrained smaller drop (Δτ ratio < 1)", "peak_velocity_ratio": "peak velocity",
          "stress_drop_ratio": "stress drop", "duration_ratio": "duration"}
_PANELS = ("type_I", "type_II", "tie", "type_I_sign", "complex", "slower", "smaller_drop",
           "peak_velocity_ratio", "stress_drop_ratio", "duration_ratio")
_MEDIANS = ("peak_velocity_ratio", "stress_drop_ratio", "duration_ratio")
_WIDE, _RIGHT = 1.0 / 1.10, 1.13           # log-x offsets of the per-pair bar and the seed strip
_MARKERS = ("o", "s", "^", "D", "v", "P")     # one per group in groups_figure


def _mid(r: dict, key: str) -> float:
    return r[f"{key}_median"] if key in _MEDIANS else r[key]


def _seed_value(rows: list[dict], perm: float, seed: str, key: str):
    for r in rows:
        if r["kappa_c"] == perm and r["seed"] == seed:
            return _mid(r, key), r["n_classified"]
    return np.nan, 0


def _panel(ax, rows: list[dict], key: str, thesis: ThesisPoint | None, legend: bool):
    c = _COLOURS[key]
    pooled = sorted((r for r in rows if r["seed"] == "all" and np.isfinite(r[f"{abscissa(r)}_median"])),
                    key=lambda r: r[f"{abscissa(r)}_median"])
    seeds = sorted({r["seed"] for r in rows if r["seed"] != "all"})
    for i, r in enumerate(pooled):
        x = abscissa(r)
        de, m = r[f"{x}_median"], _mid(r, key)
        first = legend and i == 0
        ax.plot([r[f"{x}_min"], r[f"{x}_max"]], [m, m], color="0.75", lw=0.8, zorder=1)
        lo, hi = r[f"{key}_lo"], r[f"{key}_hi"]
        if np.isfinite(lo):
            ax.errorbar([de * _WIDE], [m], yerr=[[max(m - lo, 0)], [max(hi - m, 0)]], fmt="none", ecolor="0.35",
                        elinewidth=0.9, capsize=2.5, label="per pair (Wilson / pair bootstrap)" if first else None)
        slo, shi = r.get(f"{key}_seed_lo", np.nan), r.get(f"{key}_seed_hi", np.nan)
        if np.isfinite(slo):
            ax.errorbar([de], [m], yerr=[[max(m - slo, 0)], [max(shi - m, 0)]], fmt="none", ecolor=c,
                        elinewidth=2.6, capsize=0, alpha=0.55, label="seed level (bootstrap over seeds)" if first else None)
        ax.plot([de], [m], "o", color=c, ms=6, mec="k", mew=0.5, zorder=3, label="pooled" if first else None)
        for j, seed in enumerate(seeds):
            v, n = _seed_value(rows, r["kappa_c"], seed, key)
            if np.isfinite(v) and n:
                ax.scatter([de * _RIGHT * (1.0 + 0.035 * (j - (len(seeds) - 1) / 2))], [v], s=6 + 2.5 * n,
                           facecolors="none", edgecolors=c, linewidths=0.9, zorder=2,
                           label="one seed (area ~ pairs)" if first and j == 0 else None)
    if thesis is not None and key in thesis.fractions:
        f, flo, fhi = thesis.fractions[key]
        ax.errorbar([thesis.deborah], [f], yerr=[[f - flo], [fhi - f]],
                    xerr=[[thesis.deborah - thesis.deborah_lo], [thesis.deborah_hi - thesis.deborah]],
                    fmt="*", color="k", mfc=c, ms=12, mec="k", mew=0.6, capsize=2, alpha=0.85, lw=0.8,
                    label="thesis (Wilson)" if legend else None)
    _style(ax, key)


def _style(ax, key: str):
    """A finding's panel: log De axis, its name, the ratio's 1 or the fraction's 0-1 range."""
    if key in _MEDIANS:
        ax.axhline(1.0, color="0.3", lw=0.8, ls="--")
    else:
        ax.set_ylim(-0.03, 1.03)
    ax.set_xscale("log")
    ax.set_title(_NAMES[key] + (" (median of undrained / drained)" if key in _MEDIANS else ""), fontsize=9,
                 loc="left")
    ax.grid(True, which="both", color="0.92", lw=0.6)


def regime_figure(rows: list[dict], thesis: ThesisPoint | None, path: Path, title: str = "") -> Path:
    """Write the regime map of :func:`~gouge_cli.analysis.regime.regime_rows` rows."""
    fig, axes = plt.subplots(2, 5, figsize=(18.0, 7.6), dpi=DPI, sharex=True)
    for i, (ax, key) in enumerate(zip(axes.flat, _PANELS)):
        _panel(ax, rows, key, thesis, legend=i == 0)
        if i % 5 == 0:
            ax.set_ylabel("fraction of pairs" if i == 0 else "share of pairs / ratio")
    slip_de = any(abscissa(r) == "deborah_drained" for r in rows)
    for ax in axes[1]:
        ax.set_xlabel("De of the slip (u₀: drained peak)" if slip_de else "De = l u₀ / D (undrained, largest in the slip)")
    axes.flat[0].legend(fontsize=6.5, loc="upper left")
    n_seeds = len({r["seed"] for r in rows if r["seed"] != "all"}) or 1
    note = (f"{n_seeds} seed(s); pooled ● with 95 % intervals: thick = seed level, thin = per pair; "
            "○ = single seeds" + ("; ★ = the thesis (Table 3, 39 pairs; De from its own parameters, bars: "
                                  "its range)" if thesis is not None else ""))
    fig.suptitle((title + "\n" if title else "") + note, fontsize=9)
    fig.tight_layout(rect=(0, 0, 1, 0.95))
    return save(fig, path, {"Title": title or "regime map",
                            "Description": "pair fractions and ratio medians against the Deborah number, "
                                           "per seed and pooled with seed-level and per-pair intervals"})


def delay_figure(pair_rows: list[dict], delay: list[dict], path: Path, title: str = "") -> Path:
    """Ratios against the onset delay (every classified, non-transient pair; colour: kappa_c) and
    the slower / smaller-drop shares per |delay| bin pooled over kappa_c (both intervals), each
    kappa_c's share a small marker beside it."""
    from ..analysis.regime import delay_points

    pairs = delay_points(pair_rows)
    perms = sorted({r["kappa_c"] for r in pairs})
    cmap = plt.get_cmap("viridis")
    colour = {k: cmap(i / max(1, len(perms) - 1)) for i, k in enumerate(perms)}
    fig, axes = plt.subplots(1, 3, figsize=(16.0, 4.8), dpi=DPI)
    edges = sorted({r["delay_to"] for r in delay if np.isfinite(r["delay_to"])})
    for ax, col, name in ((axes[0], "peak_velocity_ratio", "peak velocity"), (axes[1], "stress_drop_ratio", "stress drop")):
        for k in perms:
            at = [r for r in pairs if r["kappa_c"] == k]
            ax.scatter([r["delay"] for r in at], [r[col] for r in at], s=16, color=colour[k],
                       alpha=0.8, label=f"κ_c = {k:g} d²")
        ax.axhline(1.0, color="0.3", lw=0.8, ls="--")
        for e in edges:
            for sign in (-1, 1):
                ax.axvline(sign * e, color="0.7", lw=0.7, ls=":")
        ax.set_yscale("log")
        ax.set_xlabel("undrained onset − drained onset  [t₀]")
        ax.set_ylabel(f"{name}: undrained / drained")
        ax.grid(True, color="0.92", lw=0.6)
    axes[0].legend(fontsize=7)
    axes[0].set_title("(a) peak-velocity ratio (< 1: undrained slower)", fontsize=9, loc="left")
    axes[1].set_title("(b) stress-drop ratio (< 1: undrained smaller drop)", fontsize=9, loc="left")
    ax = axes[2]
    bins = sorted({(r["delay_from"], r["delay_to"]) for r in delay})
    labels = [f"{a / 1e3:g}–{b / 1e3:g}k" if np.isfinite(b) else f"≥ {a / 1e3:g}k" for a, b in bins]
    for off, key in ((-0.12, "slower"), (0.12, "smaller_drop")):
        c = _COLOURS[key]
        for i, (a, b) in enumerate(bins):
            pooled = next(r for r in delay if r["kappa_c"] == "all" and r["delay_from"] == a)
            if not pooled["n_pairs"]:
                continue
            m = pooled[key]
            ax.errorbar([i + off - 0.04], [m], yerr=[[max(m - pooled[f"{key}_lo"], 0)], [max(pooled[f"{key}_hi"] - m, 0)]],
                        fmt="none", ecolor="0.35", elinewidth=0.9, capsize=2.5,
                        label="per pair (Wilson)" if i == 0 and key == "slower" else None)
            if np.isfinite(pooled[f"{key}_seed_lo"]):
                ax.errorbar([i + off], [m], yerr=[[max(m - pooled[f"{key}_seed_lo"], 0)],
                                                  [max(pooled[f"{key}_seed_hi"] - m, 0)]],
                            fmt="none", ecolor=c, elinewidth=2.6, alpha=0.55,
                            label="seed level" if i == 0 and key == "slower" else None)
            ax.plot([i + off], [m], "o", color=c, mec="k", mew=0.5, ms=7,
                    label=f"{_NAMES[key]}, all κ_c" if i == 0 else None)
            ax.annotate(f"{pooled[f'n_{key}']}/{pooled['n_pairs']}", (i + off, m), textcoords="offset points",
                        xytext=(4, 6), fontsize=6.5)
            for j, k in enumerate(perms):
                r = next(r for r in delay if r["kappa_c"] == k and r["delay_from"] == a)
                if r["n_pairs"]:
                    ax.scatter([i + off + 0.06 + 0.012 * j], [r[key]], s=6 + 2.0 * r["n_pairs"], facecolors="none",
                               edgecolors=colour[k], linewidths=0.9)
    ax.axhline(1.0, color="0.3", lw=0.8, ls="--")
    ax.set_xticks(range(len(bins)), labels)
    ax.set_xlabel("|undrained onset − drained onset|  [t₀]")
    ax.set_ylabel("share of pairs")
    ax.set_ylim(-0.03, 1.08)
    ax.set_title("(c) shares per delay bin (○: one κ_c, area ~ pairs)", fontsize=9, loc="left")
    ax.legend(fontsize=7, loc="lower left")
    ax.grid(True, color="0.92", lw=0.6)
    if title:
        fig.suptitle(title, fontsize=9)
    fig.tight_layout(rect=(0, 0, 1, 0.95 if title else 1))
    return save(fig, path, {"Title": title or "undrained slower against onset delay",
                            "Description": "ratios and slower / smaller-drop shares against the undrained onset delay"})


def groups_figure(cells: list[GroupCell], thesis: ThesisPoint | None, path: Path, title: str = "") -> Path:
    """The findings of several groups of pairs (couplings, layer thicknesses, normal stresses: never
    pooled) on one set of axes against the measured De (``GroupCell.de_median``; the thin grey
    bar: its range over the cell's pairs): per group and permeability the pooled value with its
    seed-level 95 % interval, a group's permeabilities joined by a line, one colour and marker
    per group. cells: :func:`~gouge_cli.analysis.regime.group_cells` of every group (groups.csv's rows)."""
    fig, axes = plt.subplots(2, 3, figsize=(14.0, 7.4), dpi=DPI, sharex=True)
    cmap = plt.get_cmap("tab10")
    names = list(dict.fromkeys(c.group for c in cells))
    for g, label in enumerate(names):
        pooled = sorted((c for c in cells if c.group == label and np.isfinite(c.de_median)), key=lambda c: c.de_median)
        if not pooled:
            continue
        n_seeds = max(c.n_seeds for c in pooled)
        shift = 1.0 + 0.04 * (g - (len(names) - 1) / 2)          # (groups side by side on a log axis)
        colour, marker = cmap(g % 10), _MARKERS[g % len(_MARKERS)]
        for ax, key in zip(axes.flat, COMPARED):
            de = np.array([c.de_median for c in pooled]) * shift
            est = [c.finding(key) for c in pooled]
            mid = np.array([e.value for e in est])
            lo, hi = np.array([e.seed_lo for e in est]), np.array([e.seed_hi for e in est])
            for c, m in zip(pooled, mid):
                ax.plot([c.de_min * shift, c.de_max * shift], [m, m], color="0.8", lw=0.7, zorder=1)
            ax.plot(de, mid, "-", marker=marker, color=colour, ms=5, mec="k", mew=0.4, lw=1.0,
                    label=f"{label} ({n_seeds} seeds)")
            ok = np.isfinite(lo) & np.isfinite(hi)
            ax.errorbar(de[ok], mid[ok], yerr=[np.maximum(mid - lo, 0)[ok], np.maximum(hi - mid, 0)[ok]], fmt="none",
                        ecolor=colour, elinewidth=2.0, alpha=0.45, capsize=0)
    for ax, key in zip(axes.flat, COMPARED):
        if thesis is not None and key in thesis.fractions:
            f, flo, fhi = thesis.fractions[key]
            ax.errorbar([thesis.deborah], [f], yerr=[[f - flo], [fhi - f]], fmt="*", color="k", ms=11,
                        capsize=2, lw=0.8, label="thesis (Table 3, Wilson)")
        _style(ax, key)
    columns = sorted({c.de_column for c in cells})
    for ax in axes[1]:
        ax.set_xlabel("measured De of the slip (median)" if columns == ["deborah_drained"]
                      else f"measured De (median; {', '.join(columns)})")
    axes.flat[0].set_ylabel("fraction of pairs")
    axes.flat[3].set_ylabel("share of pairs / ratio")
    handles, labels = axes.flat[0].get_legend_handles_labels()
    fig.legend(handles, labels, fontsize=7.5, loc="lower center", ncol=min(3, len(labels)), frameon=False)
    fig.suptitle((title + ": " if title else "") + "pooled over seeds, bars: seed-level 95 % intervals; grey: the "
                 "De range of the pairs (u₀: the drained twin's peak wall speed)", fontsize=10)
    fig.tight_layout(rect=(0, 0.07, 1, 0.95))
    return save(fig, path, {"Title": title or "findings by group",
                            "Description": "pair fractions and ratio medians against the slip's Deborah number, "
                                           "one line per group of pairs (never pooled), seed-level intervals"})
