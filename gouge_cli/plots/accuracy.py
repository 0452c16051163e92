"""The work-precision figure of `gouge accuracy`: error against run time per setting."""

from __future__ import annotations

import math
from pathlib import Path


def plot_work_precision(path: Path, scene: dict | None, analytic: dict | None, scene_errors: tuple[str, ...]):
    """Error vs run time (log-log), one panel per ladder (one line per error in `scene_errors`) and
    per analytic case."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    from matplotlib.ticker import FuncFormatter, LogLocator

    panels = []
    for r in (scene or {}).get("results", []):
        if r.level.ladder not in panels:
            panels.append(r.level.ladder)
    cases = list(dict.fromkeys(r.case for r in (analytic or {}).get("rows", [])))
    total = len(panels) + len(cases)
    if total == 0:
        return
    cols = min(3, total)
    rows = math.ceil(total / cols)
    fig, axes = plt.subplots(rows, cols, figsize=(5 * cols, 4 * rows), squeeze=False)
    flat = list(axes.ravel())
    for ax, ladder in zip(flat, panels):
        group = [r for r in scene["results"] if r.level.ladder == ladder and r.errors]
        for name in scene_errors:
            pts = [(r.wall_seconds, r.errors[name], r.level.setting) for r in group
                   if r.errors.get(name, 0) > 0 and math.isfinite(r.errors[name]) and r.wall_seconds > 0]
            if pts:
                ax.loglog([p[0] for p in pts], [p[1] for p in pts], "o-", label=name)
                for p in pts:
                    ax.annotate(p[2].split("=")[-1], (p[0], p[1]), fontsize=7, alpha=0.7)
        ax.set_title(f"scene: {ladder}")
    for ax, case in zip(flat[len(panels):], cases):
        group = [r for r in analytic["rows"] if r.case == case]
        for name in group[0].errors:
            pts = [(r.wall_seconds, r.errors[name], r.value) for r in group
                   if r.errors[name] > 0 and math.isfinite(r.errors[name]) and r.wall_seconds > 0]
            if pts:
                ax.loglog([p[0] for p in pts], [p[1] for p in pts], "o-", label=name)
                for p in pts:
                    ax.annotate(f"{p[2]:.3g}", (p[0], p[1]), fontsize=7, alpha=0.7)
        ax.set_title(f"analytic: {case} ({group[0].parameter})")
    for ax in flat[:total]:
        if not ax.lines:                          # every error exactly 0 (or no timing): nothing to draw
            ax.text(0.5, 0.5, "errors all zero", ha="center", va="center", transform=ax.transAxes)
            continue
        lo, hi = ax.get_xlim()
        if hi < 3.0 * lo:                        # at least one 1, 2 or 5 x 10^k inside: a labelled tick
            centre = math.sqrt(lo * hi)
            ax.set_xlim(centre / 1.8, centre * 1.8)
        ax.xaxis.set_minor_locator(LogLocator(base=10.0, subs=(2.0, 5.0)))
        ax.xaxis.set_minor_formatter(FuncFormatter(lambda value, _: f"{value:.2g}"))
        ax.set_xlabel("run time [s]")
        ax.set_ylabel("relative error")
        ax.grid(True, which="both", alpha=0.3)
        if ax.get_legend_handles_labels()[0]:
            ax.legend(fontsize=8)
    for ax in flat[total:]:
        ax.axis("off")
    fig.tight_layout()
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(path, dpi=120)
    plt.close(fig)
