"""The velocity-step figure (analysis.dilatancy): (a) the steady porosity change against ln(V/V_1),
one colour per normal stress, each seed's points and the seed mean, with the laboratory's range of
eps as a band; (b) eps against the inertial number at V_2; (c) the undrained strengthening
measured against the one predicted from the drained dilation, with the 1:1 line.
"""

from __future__ import annotations

import math
from pathlib import Path

import matplotlib.pyplot as plt
import numpy as np

from .style import DPI, save

#: Samuelson, Elsworth and Marone (2009): eps of sheared gouge, 0.8-20 MPa.
LAB_EPS = (4.7e-5, 3.0e-4)


def plot_dilatancy(runs, cells, path: Path) -> Path:
    """`runs`: analysis.dilatancy.StepRun list; `cells`: analysis.dilatancy.cells(runs)."""
    sigmas = sorted({r.sigma for r in runs})
    colors = dict(zip(sigmas, plt.cm.viridis(np.linspace(0.1, 0.85, max(len(sigmas), 1)))))
    fig, (a, b, c) = plt.subplots(1, 3, figsize=(14.0, 4.6), dpi=DPI)
    lnr = np.linspace(0.0, math.log(max([s.ratio for r in runs for s in r.segments] + [10.0])), 20)
    a.fill_between(lnr, LAB_EPS[0] * lnr, LAB_EPS[1] * lnr, color="0.85", lw=0,
                   label=f"laboratory eps {LAB_EPS[0]:.1e}-{LAB_EPS[1]:.0e}")
    for sigma in sigmas:
        group = [r for r in runs if r.sigma == sigma]
        ratios = sorted({s.ratio for r in group for s in r.segments if s.drained})
        for r in group:
            base = r.segment(1.0, True)
            pts = [(math.log(q), r.segment(q, True).porosity - base.porosity) for q in ratios]
            a.plot(*zip(*pts), "o", ms=3, color=colors[sigma], alpha=0.45)
        mean = [np.mean([r.segment(q, True).porosity - r.segment(1.0, True).porosity for r in group]) for q in ratios]
        a.plot([math.log(q) for q in ratios], mean, "-", color=colors[sigma], lw=1.8,
               label=f"σ = {sigma:g} E ({len(group)} seeds)")
    a.set_xlabel("ln(V / V₁)")
    a.set_ylabel("φ − φ₁ (steady, drained)")
    a.set_title("(a) steady porosity after the step")
    a.legend(fontsize=7)
    for cell in cells:
        col = colors[cell.sigma]
        lo, hi = cell.eps[1], cell.eps[2]
        yerr = None if not math.isfinite(lo) else [[cell.eps[0] - lo], [hi - cell.eps[0]]]
        b.errorbar([cell.inertial], [cell.eps[0]], yerr=yerr, fmt="o" if cell.ratio == 10 else "s", color=col,
                   capsize=3, label=f"σ = {cell.sigma:g}, V₂/V₁ = {cell.ratio:g}")
    b.axhspan(*LAB_EPS, color="0.85", lw=0)
    b.axhline(0.0, color="0.3", lw=0.8)
    b.set_xscale("log")
    b.set_xlabel("inertial number I at V₂")
    b.set_ylabel("eps = Δφ / Δln V")
    b.set_title("(b) dilatancy coefficient (seed mean, 95 % t)")
    b.legend(fontsize=6)
    for r in runs:
        for q in sorted({s.ratio for s in r.segments if not s.drained and s.ratio != 1.0}):
            c.plot(r.predicted_strengthening(q), r.measured_strengthening(q), "o" if q == 10 else "s",
                   color=colors[r.sigma], ms=4, alpha=0.7)
    lims = [v for r in runs for q in {s.ratio for s in r.segments if s.ratio != 1.0}
            for v in (r.predicted_strengthening(q), r.measured_strengthening(q)) if math.isfinite(v)]
    if lims:
        lo, hi = min(0.0, min(lims)), max(lims)
        c.plot([lo, hi], [lo, hi], color="0.3", lw=0.8, label="1:1")
    c.set_xlabel("predicted Δ(τ/σ) = μ (−P_pred) / σ")
    c.set_ylabel("measured Δ(τ/σ), undrained − drained")
    c.set_title("(c) undrained strengthening (o: ×10, □: ×100)")
    c.legend(fontsize=7)
    fig.tight_layout()
    return save(fig, path, {"Title": "velocity steps: dilatancy and undrained strengthening"})
