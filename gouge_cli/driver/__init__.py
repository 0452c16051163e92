"""The one loop (Simulation), its two phases (compaction, loading) and what runs between its chunks: guards, slip detection, progress, settling."""
