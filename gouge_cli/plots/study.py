"""Figures of `gouge study` (thesis Figs. 5-12 equivalents for the whole study)."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np

from ..analysis.blockslider import EQ3_PERIOD_FACTOR
from ..analysis.catalog import find_slip, read_catalog, slip_friction
from ..analysis.forkpairs import ForkPair
from ..analysis.study import StudyRow
from ..io.runreader import RunReader
from .campaign import _COLORS, campaign_figure
from .make import undrained_friction_figure
from .series import friction_figure, overview_figure, pair_figure
from .style import new_figure, save


def study_figure(rows: list[StudyRow], path: Path, title: str = "") -> Path:
    """Left: S_u - S_d per pair against slip number, coloured by type (transient hollow).
    Right: m_eff / m_b of each drained slip (Eq. 3 fit); 1 is the rigid block of the thesis."""
    from matplotlib.ticker import MaxNLocator

    from ..io.layout import perm_text

    fig, (ax1, ax2) = new_figure("campaign", 1, 2)
    perms = sorted({float(r.kappa_c) for r in rows})
    markers = dict(zip(perms, "osD^v<>p*h"))
    for r in rows:
        d = r.S_u - r.S_d if math.isfinite(r.S_u) and math.isfinite(r.S_d) else float("nan")
        if math.isfinite(d):
            c = _COLORS.get(r.type, "0.5")
            ax1.scatter([r.slip], [d], s=30, marker=markers.get(float(r.kappa_c), "o"),
                        facecolor="none" if r.transient else c, edgecolor=c)
    ax1.axhline(0.0, color="0.3", lw=0.7)
    for t in ("I", "I-C", "II", "II-C", "tie"):
        ax1.scatter([], [], color=_COLORS[t], label=f"Type {t}", s=20)
    for perm in perms:
        ax1.scatter([], [], marker=markers[perm], facecolor="none", edgecolor="0.3", s=20,
                    label=f"κ_c = {perm_text(perm)} d²")
    ax1.scatter([], [], facecolor="none", edgecolor="0.5", s=20, label="hollow: transient slip")
    ax1.legend(fontsize=7, frameon=False, loc="upper left", bbox_to_anchor=(1.0, 1.0))
    ax1.set_xlabel("slip number")
    ax1.set_ylabel("S_u − S_d  (τ/σ)")
    drained = {r.slip: r for r in rows}.values()
    xs = [r.slip for r in drained if math.isfinite(r.m_eff_over_m_b)]
    ys = [r.m_eff_over_m_b for r in drained if math.isfinite(r.m_eff_over_m_b)]
    bad = [r.slip for r in drained if not math.isfinite(r.m_eff_over_m_b)]
    holds = [r.drained_fit_verdict == "holds" for r in drained if math.isfinite(r.m_eff_over_m_b)]
    ax2.axhspan(1 / EQ3_PERIOD_FACTOR ** 2, EQ3_PERIOD_FACTOR ** 2, color="0.92", lw=0,
                label=f"Eq. 3 applies (m_eff within {EQ3_PERIOD_FACTOR ** 2:g}× m_b)")
    ax2.plot([x for x, h in zip(xs, holds) if h], [y for y, h in zip(ys, holds) if h], "o", color="black", ms=4,
             label="drained slip, Eq. 3 fit holds")
    ax2.plot([x for x, h in zip(xs, holds) if not h], [y for y, h in zip(ys, holds) if not h], "o", ms=4,
             markerfacecolor="none", color="#d62728", label="sine fits, Eq. 3 does not apply")
    if bad:
        ax2.plot(bad, [0] * len(bad), "x", color="#d62728", label="fit failed (not drawn as a fit)")
    if ys:
        ax2.axhline(float(np.mean(ys)), color="0.4", ls="--", lw=0.8, label=f"mean {np.mean(ys):.3g}")
    ax2.set_xlabel("slip number")
    ax2.set_ylabel("m_eff / m_b = k (T_fit/π)² / m_b")
    ax2.legend(fontsize=7, frameon=True, framealpha=0.85, edgecolor="none", loc="best")
    for ax in (ax1, ax2):
        ax.grid(True, color="0.9")
        ax.xaxis.set_major_locator(MaxNLocator(integer=True))
        lo, hi = ax.get_xlim()
        if hi - lo < 2:                      # one slip: a unit-wide axis around it, integer ticks
            mid = 0.5 * (lo + hi)
            ax.set_xlim(mid - 1, mid + 1)
    fig.suptitle(title, fontsize=11)
    fig.subplots_adjust(left=0.1, right=0.98, top=0.88, bottom=0.14, wspace=0.62)
    return save(fig, path)


def study_figures(run_dir: Path, pairs: list[ForkPair], rows: list[StudyRow], out: Path,
                  notch: bool = True) -> list[Path]:
    """overview.png (loading run, slips shaded); per pair the figures of `gouge plot`:
    pair_slip_NNN_<branch>.png (drained vs undrained, thesis Figs. 7-12), friction_slip_NNN.png
    (drained mu_d(t), Eq. 7, Fig. 17) and friction_slip_NNN_<branch>.png (R/sigma, Eq. 6, Fig. 18);
    types.png (campaign) and study.png (:func:`study_figure`)."""
    out = Path(out)
    written = []
    drained_mean = {}
    with RunReader(run_dir) as reader:
        catalog = read_catalog(reader)
        written.append(overview_figure(reader, catalog, out / "overview.png"))
        for n in sorted({int(p.slip) for p in pairs}):
            fr = slip_friction(reader, find_slip(catalog, n), notch=notch)
            drained_mean[n] = fr.mean_mu_d
            written.append(friction_figure(fr, reader.info.V_s, out / f"friction_slip_{n:03d}.png",
                                           title=f"Slip {n}, drained: dynamic friction μ_d(t) (Eq. 7)"))
    for p in pairs:
        n, branch = int(p.slip), p.branch
        with RunReader(p.drained_dir) as d, RunReader(p.undrained_dir) as u:
            written.append(pair_figure(d, u, p, out / f"pair_slip_{n:03d}_{branch}.png"))
            if p.result.undrained_slip is not None:
                written.append(undrained_friction_figure(u, p, out / f"friction_slip_{n:03d}_{branch}.png", notch,
                                                         drained_mean.get(n)))
    if pairs:
        written.append(campaign_figure(pairs, out / "types.png", title=str(Path(run_dir).resolve())))
    written.append(study_figure(rows, out / "study.png", title=f"{run_dir}: strength difference of each pair "
                                                                f"and effective block mass of each drained slip"))
    return written
