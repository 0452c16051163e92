"""Time-series figures: run overview, one slip, drained/undrained pair, mu_d(t).

Thesis figures 5-12 and 17-18 and appendix C/D: tau/sigma, v_w/V_s, porosity and
wall displacement against time; drained black, undrained blue.
"""

from __future__ import annotations

import json
import math
from pathlib import Path

import numpy as np

from ..analysis.catalog import fit_slip, series_envelope, slip_window, SlipFriction
from ..analysis.forkpairs import ForkPair
from ..io.layout import branch_perm_text, perm_text
from ..io.runreader import RunReader
from ..io.slipcatalog import SlipEntry
from ..units import ResultUnits
from .style import (
    DRAINED,
    FIT,
    LABEL,
    PREDICTED,
    SLIP_SHADE,
    UNDRAINED,
    new_figure,
    save,
    shade_slips,
    tidy,
)

_QUANTITIES = (("tau_over_sigma", "tau"), ("wall_vx", "velocity"), ("porosity", "porosity"),
               ("wall_x", "displacement"))


def _params_line(reader: RunReader) -> str:
    i = reader.info
    fluid = f", κ_c = {perm_text(i.permeability)} d²" if i.permeability is not None else ", dry"
    return f"N = {i.n_grains} grains, k = {i.k:g}, V_s = {i.V_s:g}, σ = {i.sigma:g}{fluid}"


def _scaled(name: str, y: np.ndarray, reader: RunReader) -> np.ndarray:
    if name == "wall_vx":
        return y / reader.info.V_s
    if name.startswith("pressure"):
        return y / reader.info.sigma
    return y


def overview_figure(reader: RunReader, catalog: list[SlipEntry], path: Path, max_points: int = 6000) -> Path:
    """Four stacked panels against time since loading began, slips shaded (thesis Fig. 5, App. C)."""
    data = series_envelope(reader, [q for q, _ in _QUANTITIES], max_points=max_points)
    offset = reader.time_offset()
    t = data["time"] - offset
    fig, axes = new_figure("overview", 4, 1, sharex=True)
    spans = [(e.onset_time - offset, e.end_time - offset) for e in catalog]
    for ax, (name, label) in zip(axes, _QUANTITIES):
        if name in data:
            ax.plot(t, _scaled(name, data[name], reader), color=DRAINED, lw=0.7)
        else:
            ax.text(0.5, 0.5, f"no {name} series", transform=ax.transAxes, ha="center", color="0.5")
        shade_slips(ax, spans)
        ax.set_ylabel(LABEL[label])
    hi = reader.info.slip_rule.start_factor
    axes[1].axhline(hi, color="0.55", lw=0.7, ls=":", label=f"slip trigger {hi:g} V_s")
    axes[1].legend(loc="upper left", fontsize=8, frameon=False)
    axes[-1].set_xlabel(LABEL["time"])
    tidy(axes)
    info = reader.info
    fig.suptitle(f"{info.run_dir}: {len(catalog)} slips (shaded)\n{_params_line(reader)}", fontsize=11)
    fig.text(0.5, 0.008, ResultUnits.of_run(info.config, info.V_s, info.sigma).caption(), ha="center", fontsize=8,
             color="0.3")
    fig.subplots_adjust(left=0.11, right=0.97, top=0.92, bottom=0.07, hspace=0.08)
    return save(fig, path)


def slip_figure(reader: RunReader, entry: SlipEntry, path: Path, pad: float = 1.0) -> Path:
    """One slip magnified (thesis Fig. 6): the four quantities against time since onset, with the
    block-slider fit of Eq. 3 and the Eq. 3 curve of period 2 pi sqrt(m_b/k) on the velocity."""
    info = reader.info
    i0, i1, j0, j1 = slip_window(reader, entry, pad)
    s = reader.series([q for q, _ in _QUANTITIES] + ["time"], j0, j1)
    onset, end = entry.onset_time, entry.end_time
    t = s["time"] - onset
    fig, axes = new_figure("slip", 4, 1, sharex=True)
    for ax, (name, label) in zip(axes, _QUANTITIES):
        if s[name] is not None:
            ax.plot(t, _scaled(name, s[name], reader), color=DRAINED, lw=1.0, marker=".", ms=2.5)
        shade_slips(ax, [(0.0, end - onset)])
        ax.set_ylabel(LABEL[label])
    fit = fit_slip(reader, entry)
    ax = axes[1]
    if fit.verdict == "holds":
        tt = np.linspace(max(fit.t0, s["time"][0]), min(fit.t0 + fit.half_period, s["time"][-1]), 200)
        ax.plot(tt - onset, fit.amplitude * np.sin(fit.omega * (tt - fit.t0)) / info.V_s, color=FIT, lw=1.5,
                ls="--", label=f"Eq. 3 fit: half period {fit.half_period:.4g} t₀, R² = {fit.r2:.2f}, "
                               f"m_eff = {fit.m_eff / info.m_b:.3g} m_b")
        omega = math.sqrt(info.k / info.m_b)
        tp = np.linspace(0.0, min(math.pi / omega, float(t[-1])), 200)
        ax.plot(tp, fit.amplitude * np.sin(omega * tp) / info.V_s, color=PREDICTED, lw=1.2, ls=":",
                label=f"Eq. 3, π√(m_b/k) = {info.predicted_half_period:.4g} t₀, same amplitude")
        ax.legend(loc="upper left", fontsize=8, frameon=True, framealpha=0.85, edgecolor="none")
    axes[0].axhline(entry.static_strength, color="0.5", lw=0.7, ls=":")
    axes[0].set_xlim(float(t[0]), float(t[-1]))
    axes[-1].set_xlabel(LABEL["time_onset"])
    tidy(axes)
    units = ResultUnits.of_run(info.config, info.V_s, info.sigma)
    duration = entry.duration
    fig.suptitle(f"{info.run_dir}, slip {entry.number}: duration {duration:.4g} t₀ "
                 f"({duration * units.t0_s * 1e6:.3g} µs), peak {entry.peak_velocity / info.V_s:.3g} V_s, "
                 f"Δτ/σ = {entry.stress_drop:.3g}\n{_params_line(reader)}"
                 + ("" if fit.verdict == "holds" else f"\nEq. 3 fit not drawn: {fit.verdict_reason}"), fontsize=10)
    fig.text(0.5, 0.008, units.caption(), ha="center", fontsize=8, color="0.3")
    fig.subplots_adjust(left=0.11, right=0.97, top=0.92 if fit.verdict == "holds" else 0.9, bottom=0.07, hspace=0.08)
    return save(fig, path, metadata={"Title": f"slip {entry.number}", "Description": json.dumps(
        {"fit_drawn": fit.verdict == "holds", "verdict": fit.verdict, "reason": fit.verdict_reason})})


def pair_figure(drained: RunReader, undrained: RunReader, pair: ForkPair, path: Path) -> Path:
    """Drained (black) vs undrained (blue) from the same packing (thesis Figs. 7-12, App. D):
    tau/sigma, v_w/V_s, porosity, displacement, and the undrained pore pressure mean/min/max."""
    names = [q for q, _ in _QUANTITIES] + ["time", "pressure_mean", "pressure_min", "pressure_max"]
    d = drained.series(names)
    u = undrained.series(names)
    offset = drained.time_offset()
    td, tu = d["time"] - offset, u["time"] - offset
    fig, axes = new_figure("pair", 5, 1, sharex=True)
    res = pair.result
    for slip, color in ((res.drained_slip, DRAINED), (res.undrained_slip, UNDRAINED)):
        if slip is not None:
            for ax in axes:
                ax.axvspan(slip.onset_time - offset, slip.end_time - offset, color=color, alpha=0.08, lw=0)
    for ax, (name, label) in zip(axes, _QUANTITIES):
        if d[name] is not None:
            ax.plot(td, _scaled(name, d[name], drained), color=DRAINED, lw=1.0, label="drained")
        if u[name] is not None:
            ax.plot(tu, _scaled(name, u[name], undrained), color=UNDRAINED, lw=1.0,
                    label=f"κ_c = {branch_perm_text(undrained.info.run_dir.name)} d²")
        ax.set_ylabel(LABEL[label])
    axes[0].legend(loc="lower left", fontsize=8, frameon=False)
    ax = axes[4]
    if u["pressure_mean"] is not None:
        sig = undrained.info.sigma
        ax.fill_between(tu, u["pressure_min"] / sig, u["pressure_max"] / sig, color=UNDRAINED, alpha=0.2,
                        lw=0, label="min – max")
        ax.plot(tu, u["pressure_mean"] / sig, color=UNDRAINED, lw=1.0, label="mean")
        ax.axhline(0.0, color="0.4", lw=0.6)
        ax.legend(loc="upper left", fontsize=8, frameon=False, ncol=2)
    else:
        ax.text(0.5, 0.5, "no pore-pressure series", transform=ax.transAxes, ha="center", color="0.5")
    ax.set_ylabel(LABEL["pressure"])
    axes[-1].set_xlabel(LABEL["time"])
    tidy(axes)
    row = pair.row
    import textwrap

    parts = [f"Slip {row['slip']}: drained (black) against {branch_label(row)} (blue)", pair_verdict(row),
             *(x for x in (row["fit_reason"], row["note"]) if x)]
    title = "\n".join(textwrap.fill(p, 115) for p in parts)
    fig.suptitle(title, fontsize=9, y=0.995)
    units = ResultUnits.of_run(undrained.info.config, undrained.info.V_s, undrained.info.sigma)
    fig.text(0.5, 0.006, units.caption(), ha="center", fontsize=8, color="0.3")
    fig.subplots_adjust(left=0.11, right=0.97, top=0.985 - 0.0125 * (title.count("\n") + 1), bottom=0.055,
                        hspace=0.08)
    shaded = {"type": row["type"], "slip": row["slip"], "branch": row["branch"],
              "drained": [row["drained_onset"], row["drained_end"]],
              "undrained": [row["undrained_onset"], row["undrained_end"]]}
    return save(fig, path, metadata={"Title": title, "Description": json.dumps(shaded)})


_CRITERIA_TEXT = {"subevents": "several sub-events", "restart": "slip stops and restarts",
                  "creep": "long slow creep", "fit": "Eq. 3 does not fit the undrained slip",
                  "slow": "slow slip below the trigger"}


def pair_verdict(row: dict) -> str:
    """The pair's type in words (thesis Type I: undrained weaker, II: stronger, -C: complex)."""
    base = row["base_type"]
    if base == "none":
        return "no pair: one branch did not slip"
    if base == "failed":
        return f"no pair: {row.get('note') or 'a branch failed'}"
    what = {"I": "undrained weaker before slip", "II": "undrained stronger before slip",
            "tie": "same strength before slip"}[base]
    what = f"{'Type ' if base != 'tie' else ''}{row['type']} ({what}"
    if np.isfinite(row["strength_difference"]):
        what += f", S_u − S_d = {row['strength_difference']:+.3g} τ/σ"
    what += ")"
    if row["criteria"]:
        what += "; complex: " + ", ".join(_CRITERIA_TEXT.get(c, c) for c in row["criteria"].split(","))
    return what


def friction_figure(friction: SlipFriction, V_s: float, path: Path, title: str = "",
                    drained_mean: float | None = None) -> Path:
    """mu_d(t) (Eq. 7; undrained: R/sigma of Eq. 6) with v_w/V_s on a second axis (thesis Figs. 17-18).

    Unfiltered values thin grey, notch-filtered thick; dashed: mean over the central half of the
    slip; dotted: static strength; red (undrained): the drained twin's mean mu_d.
    """
    f = friction
    t = f.t - f.onset_time
    color = DRAINED if f.drained else UNDRAINED
    fig, ax = new_figure("friction")
    ax.axvspan(0.0, f.end_time - f.onset_time, color=SLIP_SHADE, alpha=0.2, lw=0, zorder=0)
    if f.filtered is not None:
        ax.plot(t, f.friction, color="0.7", lw=0.7, label="unfiltered")
        ax.plot(t, f.filtered, color=color, lw=1.6,
                label=f"notch-filtered ({f.notch_frequency:.3g} / t₀)")
    else:
        ax.plot(t, f.friction, color=color, lw=1.3, label="unfiltered")
    ax.axhline(f.mu_s, color="black", lw=0.9, ls=":", label=f"static strength {f.mu_s:.4g}")
    ax.axhline(f.mean_mu_d, color=color, lw=0.9, ls="--", label=f"mean during slip {f.mean_mu_d:.4g}")
    if drained_mean is not None and np.isfinite(drained_mean):
        ax.axhline(drained_mean, color=FIT, lw=1.0, label=f"drained mean μ_d {drained_mean:.4g}")
    ax.set_xlabel(LABEL["time_onset"])
    ax.set_ylabel(f.label, color=color)
    ax.grid(True, color="0.9", lw=0.6)
    ax2 = ax.twinx()
    ax2.plot(t, f.v_wall / V_s, color="tab:orange", lw=1.0, alpha=0.9, label="v_w / V_s (right axis)")
    ax2.set_ylabel(LABEL["velocity"], color="tab:orange")
    ax2.tick_params(axis="y", colors="tab:orange")
    handles, labels = ax.get_legend_handles_labels()
    h2, l2 = ax2.get_legend_handles_labels()
    fig.legend(handles + h2, labels + l2, loc="upper center", bbox_to_anchor=(0.5, 0.915), ncol=3,
               fontsize=7.5, frameon=False)
    ax.set_zorder(ax2.get_zorder() + 1)
    ax.patch.set_visible(False)
    note = f"  [{f.note}]" if f.note else ""
    fig.suptitle((title or f"slip {f.number}") + note, fontsize=10, y=0.98)
    fig.subplots_adjust(left=0.1, right=0.9, top=0.78, bottom=0.11)
    return save(fig, path)


def branch_colors(perms) -> dict:
    """One colour per permeability, from a sequential scale ordered by log kappa_c (the same
    colour for the same kappa_c in every panel)."""
    import matplotlib

    perms = sorted(set(float(p) for p in perms))
    cmap = matplotlib.colormaps["viridis"]
    if len(perms) == 1:
        return {perms[0]: UNDRAINED}
    logs = np.log10(perms)
    span = logs.max() - logs.min() or 1.0
    return {p: cmap(0.05 + 0.8 * (lp - logs.min()) / span) for p, lp in zip(perms, logs)}


def branch_label(row: dict) -> str:
    """Legend text of an undrained branch: kappa_c, its Deborah number and drainage regime."""
    de = row.get("deborah_slip")
    de = de if de is not None and np.isfinite(de) else row.get("deborah_mean", float("nan"))
    return f"κ_c = {perm_text(row['permeability'])} d², De = {de:.3g} ({row['regime']})"


def comparison_figure(drained: RunReader, branches: list, path: Path) -> Path:
    """One slip, the drained branch and every permeability on shared axes: tau/sigma, v_w/V_s and
    the pore pressure (mean line, min-max band) against time since loading began (second axis: the
    same time in ms), one colour per kappa_c (:func:`branch_colors`), its Deborah number in the
    legend. ``branches``: (RunReader, ForkPair) of each undrained branch."""
    from ..units import ResultUnits

    names = ["time", "tau_over_sigma", "wall_vx", "pressure_mean", "pressure_min", "pressure_max"]
    info = drained.info
    units = ResultUnits.of_run(info.config, info.V_s, info.sigma)
    offset = drained.time_offset()
    fig, axes = new_figure("pair", 3, 1, sharex=True)
    d = drained.series(names)
    axes[0].plot(d["time"] - offset, d["tau_over_sigma"], color=DRAINED, lw=1.1, label="drained (dry)")
    axes[1].plot(d["time"] - offset, d["wall_vx"] / info.V_s, color=DRAINED, lw=1.1, label="drained (dry)")
    colors = branch_colors([p.permeability for _, p in branches])
    p_max = 0.0
    for reader, pair in branches:
        u = reader.series(names)
        tu = u["time"] - reader.time_offset()
        c = colors[float(pair.permeability)]
        label = branch_label(pair.row)
        axes[0].plot(tu, u["tau_over_sigma"], color=c, lw=1.0, label=label)
        axes[1].plot(tu, u["wall_vx"] / reader.info.V_s, color=c, lw=1.0, label=label)
        if u["pressure_mean"] is not None:
            sig = reader.info.sigma
            axes[2].fill_between(tu, u["pressure_min"] / sig, u["pressure_max"] / sig, color=c, alpha=0.18, lw=0)
            axes[2].plot(tu, u["pressure_mean"] / sig, color=c, lw=1.0, label=label)
            p_max = max(p_max, float(np.nanmax(np.abs(u["pressure_min"] / sig))),
                        float(np.nanmax(np.abs(u["pressure_max"] / sig))))
    axes[2].axhline(0.0, color="0.4", lw=0.6)
    if p_max > 0:
        axes[2].set_ylim(-1.05 * p_max, 1.05 * p_max)
    for ax, label in zip(axes, ("tau", "velocity", "pressure")):
        ax.set_ylabel(LABEL[label])
    axes[2].set_ylabel("P / σ  (mean; band: min – max)")
    axes[1].axhline(info.slip_rule.start_factor, color="0.55", lw=0.7, ls=":")
    axes[0].legend(loc="lower left", fontsize=8, frameon=True, framealpha=0.85, edgecolor="none")
    axes[-1].set_xlabel(LABEL["time"])
    scale = units.t0_s * 1e3
    top = axes[0].secondary_xaxis("top", functions=(lambda t: t * scale, lambda s: s / scale))
    top.set_xlabel("time since loading began [ms]", fontsize=9)
    top.tick_params(labelsize=8)
    tidy(axes)
    slip = int(info.fork_slip) if info.fork_slip is not None else 0
    perms = ", ".join(perm_text(p.permeability) for _, p in branches)
    title = f"Slip {slip}: drained branch and every permeability (κ_c = {perms} d²) from the same packing"
    fig.suptitle(title, fontsize=10.5, y=0.985)
    fig.text(0.5, 0.008, units.caption() + "; v_w / V_s: dotted line = slip trigger", ha="center", fontsize=8,
             color="0.3")
    fig.subplots_adjust(left=0.11, right=0.97, top=0.91, bottom=0.07, hspace=0.08)
    return save(fig, path, metadata={"Title": title, "Description": json.dumps(
        {"slip": slip, "branches": [{"branch": p.branch, "permeability": p.permeability,
                                     "deborah_slip": p.measured.deborah_slip, "regime": p.measured.regime}
                                    for _, p in branches]}, allow_nan=True)})
