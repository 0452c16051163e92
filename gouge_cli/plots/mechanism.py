"""The mechanism figures (analysis.mechanism): the sign test and the pressure collapse.

:func:`sign_figure`: S_u - S_d of every pair against its drained twin's volumetric strain from
the fork to the onset, one colour per permeability; the quadrants where the sign predicts the type
(dilation and Type II, compaction and Type I) are shaded, and the legend gives each
permeability's fraction predicted with its seed-level interval.

:func:`collapse_figure`: (a) peak |P| / (|eps_v| / (beta phi)) against t_D / t_w (log-log), one
colour per permeability, with the drained layer's response to a steady strain rate
(analysis.mechanism.layer_response) and the factor-3 band around it; (b) the measured peak |P|
against the pressure the undrained branch's own strain rate sustains (the rate test), with the
1:1 line and the same band.
"""

from __future__ import annotations

from pathlib import Path

import matplotlib.pyplot as plt
import numpy as np

from ..analysis.mechanism import SCATTER_FACTOR, collapse_point, layer_response, rate_agrees, rate_point
from ..analysis.regime import _flag, _num
from ..io.layout import perm_text
from .series import branch_colors
from .style import DPI, save


def _by_perm(pair_rows: list[dict]) -> dict[float, list[dict]]:
    groups: dict[float, list[dict]] = {}
    for r in pair_rows:
        if not _flag(r, "transient"):
            groups.setdefault(_num(r, "permeability"), []).append(r)
    return dict(sorted(groups.items()))


def _pooled(rows: list[dict], perm: float) -> dict | None:
    return next((r for r in rows if r["seed"] == "all" and r["kappa_c"] == perm), None)


def sign_figure(pair_rows: list[dict], mech_rows: list[dict], path: Path, title: str = "") -> Path:
    groups = _by_perm(pair_rows)
    colors = branch_colors(list(groups))
    fig, ax = plt.subplots(figsize=(7.2, 5.0), dpi=DPI)
    ax.axhline(0.0, color="0.3", lw=0.8)
    ax.axvline(0.0, color="0.3", lw=0.8)
    for perm, rows in groups.items():
        pts = np.array([(_num(r, "drained_dilation"), _num(r, "strength_difference")) for r in rows
                        if str(r.get("base_type")) in ("I", "II", "tie")], dtype=float).reshape(-1, 2)
        pts = pts[np.all(np.isfinite(pts), axis=1)]
        m = _pooled(mech_rows, perm)
        label = f"κ_c = {perm_text(perm)} d²"
        if m is not None and m["n_signed"]:
            label += (f": sign predicts {m['n_predicted']}/{m['n_signed']} = {m['predicted']:.2f}"
                      + (f" [{m['predicted_seed_lo']:.2f}, {m['predicted_seed_hi']:.2f}] seed-level"
                         if np.isfinite(m["predicted_seed_lo"]) else ""))
        ax.scatter(pts[:, 0], pts[:, 1], s=14, color=colors[perm], alpha=0.8, label=label)
    x0, x1 = ax.get_xlim()
    y0, y1 = ax.get_ylim()
    ax.fill_between([0, max(x1, 0)], 0, max(y1, 0), color="#1f5fbf", alpha=0.06, lw=0)
    ax.fill_between([min(x0, 0), 0], min(y0, 0), 0, color="#d62728", alpha=0.06, lw=0)
    ax.set_xlim(x0, x1)
    ax.set_ylim(y0, y1)
    ax.text(0.98, 0.97, "dilation → Type II", transform=ax.transAxes, ha="right", va="top", fontsize=8,
            color="#1f5fbf")
    ax.text(0.02, 0.03, "compaction → Type I", transform=ax.transAxes, ha="left", va="bottom", fontsize=8,
            color="#d62728")
    ax.set_xlabel("drained twin's volumetric strain, fork → onset  [-]")
    ax.set_ylabel("S_u − S_d  [τ/σ]")
    ax.legend(fontsize=7, loc="best")
    ax.grid(True, color="0.92", lw=0.6)
    if title:
        ax.set_title(title, fontsize=9, loc="left")
    return save(fig, path)


def collapse_figure(pair_rows: list[dict], mech_rows: list[dict], path: Path, title: str = "") -> Path:
    groups = _by_perm(pair_rows)
    colors = branch_colors(list(groups))
    fig, (ax, ax2) = plt.subplots(1, 2, figsize=(13.0, 5.0), dpi=DPI)
    _rate_panel(ax2, groups, colors, mech_rows)
    xs = []
    for perm, rows in groups.items():
        pts = np.array([collapse_point(r) for r in rows], dtype=float).reshape(-1, 2)
        pts = pts[np.all(np.isfinite(pts), axis=1)]
        xs += list(pts[:, 0])
        m = _pooled(mech_rows, perm)
        label = f"κ_c = {perm_text(perm)} d²"
        if m is not None and m["n_collapse"]:
            label += (f": {m['n_collapse']} pairs, median / curve {m['collapse_ratio_median']:.2f}, "
                      f"{100 * m['collapse_within_factor']:.0f} % within ×{SCATTER_FACTOR:g}")
        ax.scatter(pts[:, 0], pts[:, 1], s=14, color=colors[perm], alpha=0.8, label=label)
    lo, hi = (min(xs) / 2, max(xs) * 2) if xs else (1e-2, 1e2)
    x = np.logspace(np.log10(min(lo, 0.05)), np.log10(max(hi, 20.0)), 200)
    ref = layer_response(x)
    ax.plot(x, ref, color="k", lw=1.2, label="layer drained at both walls, steady strain rate over t_w")
    ax.fill_between(x, ref / SCATTER_FACTOR, ref * SCATTER_FACTOR, color="0.5", alpha=0.12, lw=0,
                    label=f"factor {SCATTER_FACTOR:g}")
    _log_panel(ax, "t_D / t_w  (diffusion time l²/D over fork → undrained onset)",
               "peak |P| / (|ε_v| / (β φ)), ε_v the drained twin's, fork → onset",
               "(a) the drained twin's mean strain over the window", "lower right")
    if title:
        fig.suptitle(title, fontsize=10)
    return save(fig, path)


def _rate_panel(ax, groups: dict, colors: dict, mech_rows: list[dict]):
    """Measured peak |P| against the undrained branch's own strain rate's quasi-steady pressure;
    filled where the signs agree, open where not."""
    lo, hi = np.inf, 0.0
    for perm, rows in groups.items():
        pts = [(rate_point(r), rate_agrees(r)) for r in rows]
        pts = [(p, a) for p, a in pts if np.isfinite(p[0])]
        if not pts:
            continue
        xy = np.array([p for p, _ in pts])
        agree = np.array([a for _, a in pts], dtype=bool)
        lo, hi = min(lo, xy.min()), max(hi, xy.max())
        m = _pooled(mech_rows, perm)
        label = f"κ_c = {perm_text(perm)} d²"
        if m is not None and m["n_rate"]:
            label += (f": same sign {m['rate_sign_agrees']}/{m['n_rate']}, median measured / predicted "
                      f"{m['rate_ratio_median']:.2f}, {100 * m['rate_within_factor']:.0f} % within ×{SCATTER_FACTOR:g}")
        ax.scatter(xy[agree, 0], xy[agree, 1], s=16, color=colors[perm], alpha=0.85, label=label)
        ax.scatter(xy[~agree, 0], xy[~agree, 1], s=16, facecolors="none", edgecolors=colors[perm], alpha=0.85)
    if hi > 0:
        x = np.array([lo / 3, hi * 3])
        ax.plot(x, x, color="k", lw=1.0, label="measured = predicted")
        ax.fill_between(x, x / SCATTER_FACTOR, x * SCATTER_FACTOR, color="0.5", alpha=0.12, lw=0)
    _log_panel(ax, "|P| predicted: (t_D / 3) |ε_v'| / (β φ), the undrained branch's rate at the peak  [E]",
               "peak |P| measured, fork → undrained onset  [E]",
               "(b) the strain rate of the moment (open: signs differ)", "upper left")


def _log_panel(ax, xlabel: str, ylabel: str, title: str, legend: str):
    ax.set_xscale("log")
    ax.set_yscale("log")
    ax.set_xlabel(xlabel)
    ax.set_ylabel(ylabel)
    ax.legend(fontsize=7, loc=legend)
    ax.grid(True, which="both", color="0.92", lw=0.6)
    ax.set_title(title, fontsize=9, loc="left")
