"""Shared look of the figures: sizes, colours, axis labels (all quantities dimensionless)."""

from __future__ import annotations

from pathlib import Path

import matplotlib.pyplot as plt

from ..io.outputs import temporary

DPI = 120
# figure sizes in inches (pixel size = inches * DPI; no tight bbox, so sizes are exact)
FIGSIZE = {
    "overview": (9.0, 9.0),
    "slip": (9.0, 9.0),
    "pair": (9.0, 11.0),
    "friction": (9.0, 4.8),
    "campaign": (10.0, 4.2),
}

DRAINED = "black"
UNDRAINED = "#1f5fbf"       # thesis: drained black, undrained blue
SLIP_SHADE = "#f4a261"
FIT = "#d62728"
PREDICTED = "0.45"

LABEL = {
    "time": "t / t₀  (since loading began)",
    "time_onset": "t − t_onset  / t₀",
    "tau": "τ / σ",
    "velocity": "v_w / V_s",
    "porosity": "porosity φ",
    "displacement": "x_w / d",
    "pressure": "P / σ",
    "x": "x / d",
    "z": "z / d",
}


def new_figure(kind: str, nrows: int = 1, ncols: int = 1, **kwargs):
    fig, axes = plt.subplots(nrows, ncols, figsize=FIGSIZE[kind], dpi=DPI, **kwargs)
    return fig, axes


def save(fig, path: Path, metadata: dict | None = None) -> Path:
    """Write ``fig`` as PNG at :data:`DPI` (exact figure size) and close it; ``metadata``: PNG
    text chunks (e.g. {"Title": ..., "Description": ...}) so tests can read what a figure says."""
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    try:
        with temporary(path) as tmp:         # renamed when complete: a full disk leaves no partial figure
            fig.savefig(tmp, dpi=DPI, format="png", metadata=metadata)
    finally:
        plt.close(fig)
    return path


def shade_slips(ax, spans, color: str = SLIP_SHADE, alpha: float = 0.3):
    """Shade each ``(t_start, t_end)`` span of ``spans`` on ``ax``."""
    for a, b in spans:
        ax.axvspan(a, b, color=color, alpha=alpha, lw=0, zorder=0)


def tidy(axes):
    """Grid and shared-x cleanup for stacked panels."""
    for ax in axes:
        ax.grid(True, color="0.9", lw=0.6)
        ax.tick_params(labelsize=9)
    for ax in axes[:-1]:
        ax.tick_params(labelbottom=False)
