"""gouge: grain-scale simulations of water-saturated fault gouge (2D DEM + Goren pore fluid)."""

__version__ = "0.2.0"

# numba's cache folder is chosen (per digest of the kernel sources) when gouge is imported
from .kernels import NUMBA_CACHE  # noqa: E402,F401
