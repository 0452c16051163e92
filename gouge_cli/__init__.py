"""gouge: grain-scale simulations of water-saturated fault gouge (2D DEM + Goren pore fluid).

The Python API (``import gouge_cli as gouge``): open_run, open_study, open_campaign, analyze, figures,
run, restart, study -- see gouge_cli.api. They are imported on first use (PEP 562), so ``import gouge_cli`` stays light.
"""

__version__ = "0.2.0"

# numba's cache folder is chosen (per digest of the kernel sources) when gouge is imported
from .kernels import NUMBA_CACHE  # noqa: E402,F401

API = ("open_run", "open_study", "open_campaign", "analyze", "figures", "run", "restart", "study")


def __getattr__(name: str):
    """gouge_cli.open_run etc.: the names of gouge_cli.api (the package's one upward import)."""
    if name in API:
        from . import api

        return getattr(api, name)
    raise AttributeError(f"module 'gouge_cli' has no attribute {name!r}")


def __dir__():
    return sorted(list(globals()) + list(API))
