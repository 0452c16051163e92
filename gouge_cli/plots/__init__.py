"""Figures (PNG) from run files; reads outputs only, never the simulation.

The Agg backend is selected here, before any pyplot import, so figures render
without a display. Entry point: :func:`make_figures` (what `gouge plot` calls).
"""

import matplotlib

matplotlib.use("Agg")

from .campaign import campaign_figure  # noqa: E402
from .make import make_figures  # noqa: E402
from .series import friction_figure, overview_figure, pair_figure, slip_figure  # noqa: E402
from .snapshot import snapshot_figure, snapshot_figsize  # noqa: E402
from .style import DPI, FIGSIZE  # noqa: E402

__all__ = [
    "DPI",
    "FIGSIZE",
    "campaign_figure",
    "friction_figure",
    "make_figures",
    "overview_figure",
    "pair_figure",
    "slip_figure",
    "snapshot_figure",
    "snapshot_figsize",
]
