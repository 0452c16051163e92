"""Plot helpers for the Python API (gouge_cli.api): each draws on a matplotlib Axes (a new one when
none is given) and returns it, so figures can be composed in a notebook.

They take the API's objects by what they hold (a Run's ``series`` Dataset and ``info``, a Pair's
``series``, ``fit_curve`` and ``events``, a pandas table), in the look of the `gouge plot` figures:
drained black, undrained blue, Eq. 3 fits red.
"""

from __future__ import annotations

import matplotlib.pyplot as plt
import numpy as np

from .style import DRAINED, FIT, LABEL, SLIP_SHADE, UNDRAINED

__all__ = ["wall_velocity", "series", "table_scatter"]

_COLOR = {"drained": DRAINED, "undrained": UNDRAINED}


def _axes(ax):
    if ax is None:
        _, ax = plt.subplots(figsize=(8.0, 4.0))
    return ax


def wall_velocity(pair, ax=None, fit: bool = True, since_onset: bool = True, shade: bool = True):
    """Top-wall velocity v_w / V_s of both branches of a pair on one time axis, with the Eq. 3
    block-slider fit of each branch's compared slip where its verdict is "holds" (thesis Figs. 6-12;
    a failed or inapplicable fit is named in a note, not drawn). Time: since the drained compared
    slip's onset (``since_onset``) or since loading began [t0]. Returns the Axes."""
    ax = _axes(ax)
    ds = pair.series
    V_s = float(pair.drained.info.V_s)
    events = pair.events
    origin = 0.0
    if since_onset and events["drained"] is not None:
        origin = float(events["drained"].onset_time)          # since loading (Pair.events)
    t = ds["time"].values - origin
    notes = []
    for branch in ("drained", "undrained"):
        v = ds["wall_vx"].sel(branch=branch).values / V_s
        label = "drained" if branch == "drained" else f"undrained ({pair.branch})"
        ax.plot(t, v, color=_COLOR[branch], lw=1.0, label=label)
        event = events[branch]
        if shade and event is not None:
            ax.axvspan(event.onset_time - origin, event.end_time - origin,
                       color=_COLOR[branch], alpha=0.08, lw=0)
        f = pair.fits[branch] if fit else None
        if f is None:
            continue
        if f.verdict != "holds":
            notes.append(f"Eq. 3 fit not drawn, {branch}: {f.verdict_reason}")
            continue
        curve = pair.fit_curve(branch)
        if curve is None:
            continue
        ax.plot(curve["time"].values - origin, curve.values / V_s, color=FIT, lw=1.4,
                ls="--" if branch == "drained" else ":",
                label=f"Eq. 3 fit, {branch}: half period {f.half_period:.4g} t₀, R² = {f.r2:.2f}")
    if notes:
        ax.text(0.99, 0.02, "\n".join(notes), transform=ax.transAxes, ha="right", va="bottom", fontsize=7,
                color="0.3")
    ax.set_xlabel(LABEL["time_onset"] if since_onset and events["drained"] is not None else LABEL["time"])
    ax.set_ylabel(LABEL["velocity"])
    ax.set_title(f"slip {pair.row['slip']}: drained vs {pair.branch}, Type {pair.type}", fontsize=10)
    ax.grid(True, color="0.9", lw=0.6)
    ax.legend(loc="upper left", fontsize=8, frameon=False)
    return ax


def series(run, names=("tau_over_sigma",), ax=None, slips: bool = True, color: str = DRAINED):
    """Series of a run (variables of ``run.series``) against time since loading [t0], the unit of
    each in the legend; slips shaded from ``run.slips``. Returns the Axes."""
    ax = _axes(ax)
    ds = run.series
    names = [names] if isinstance(names, str) else list(names)
    for name in names:
        var = ds[name]
        ax.plot(ds["time"].values, var.values, lw=0.8, color=color if len(names) == 1 else None,
                label=f"{name} [{var.attrs['units']}]")
    if slips and len(run.slips):
        df = run.slips
        for a, b in zip(df["onset_time"], df["end_time"]):
            ax.axvspan(a, b, color=SLIP_SHADE, alpha=0.3, lw=0, zorder=0)
    ax.set_xlabel(LABEL["time"])
    ax.grid(True, color="0.9", lw=0.6)
    ax.legend(loc="best", fontsize=8, frameon=False)
    return ax


def table_scatter(table, x: str, y: str, by: str | None = "type", ax=None, logx: bool | None = None):
    """One point per row of a pandas table (open_study / open_campaign pairs, run.slips), ``y``
    against ``x``, one colour per value of ``by``. A log x axis for permeability by default."""
    ax = _axes(ax)
    groups = table.groupby(by, sort=True) if by else [(None, table)]
    for key, rows in groups:
        ax.plot(rows[x], rows[y], ls="none", marker="o", ms=5, alpha=0.8, label=None if key is None else str(key))
    if logx if logx is not None else (x in ("permeability", "kappa_c") and np.all(table[x] > 0)):
        ax.set_xscale("log")
    units = table.attrs.get("units", {})
    ax.set_xlabel(f"{x} [{units[x]}]" if x in units else x)
    ax.set_ylabel(f"{y} [{units[y]}]" if y in units else y)
    ax.grid(True, color="0.9", lw=0.6)
    if by:
        ax.legend(title=by, fontsize=8, frameon=False)
    return ax
