"""gouge: grain-scale simulations of water-saturated fault gouge (2D DEM + Goren pore fluid)."""

import os

__version__ = "0.1.0"

# numba compiles kernels once per machine and caches them next to the sources.
NUMBA_CACHE = os.environ.get("GOUGE_NUMBA_CACHE", "1") != "0"
