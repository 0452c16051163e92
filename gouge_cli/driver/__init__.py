"""The one loop (Simulation) and what runs between its chunks: guards, slip detection, progress, settling."""
