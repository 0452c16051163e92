"""Figure of the stick-scaling ladder (gouge_cli.studies.scaling_ladder): slip statistics and cost vs lambda."""

from __future__ import annotations

from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402

from .style import DPI  # noqa: E402

_NAMES = {"static_strength": "static strength τ_s/σ", "stress_drop": "stress drop Δτ/σ",
          "recurrence": "recurrence time / t₀", "peak_velocity": "peak velocity / v₀",
          "duration": "slip duration / t₀"}


def plot_ladder(result: dict, path: Path) -> Path:
    """Six panels: per slip quantity the difference from lambda = 1 (mean, 95 % CI) with the
    lambda = 1 seed-to-seed spread shaded; and grain-steps per loading cycle vs lambda."""
    rows = result["rows"]
    lams = [r["lambda"] for r in rows]
    fig, axes = plt.subplots(2, 3, figsize=(12.0, 7.0), dpi=DPI)
    for ax, q in zip(axes.flat, _NAMES):
        diff = [r[f"{q}_diff"] for r in rows]
        ci = [r[f"{q}_ci95"] for r in rows]
        spread = rows[0][f"{q}_spread"]
        ax.axhspan(-spread, spread, color="0.85", label="λ = 1 seed-to-seed spread")
        ax.axhline(0.0, color="0.5", lw=0.8)
        ax.errorbar(lams, diff, yerr=ci, fmt="o-", color="black", capsize=3, label="mean difference, 95 % CI")
        ax.set_xscale("log", base=2)
        ax.set_xlabel("stick scaling λ")
        ax.set_title(f"Δ {_NAMES[q]}", fontsize=10)
    axes.flat[0].legend(fontsize=7)
    ax = axes.flat[5]
    ax.loglog(lams, [r["grain_steps_per_cycle"] for r in rows], "o-", color="black", base=2)
    ax.set_xlabel("stick scaling λ")
    ax.set_title("grain-steps per loading cycle", fontsize=10)
    ax.axvline(result["default"], color="#d62728", ls="--", label=f"default λ = {result['default']:g}")
    ax.legend(fontsize=7)
    fig.tight_layout()
    fig.savefig(path)
    plt.close(fig)
    return Path(path)
