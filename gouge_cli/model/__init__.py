"""The scene (Scene: a checked config and what it derives), arrays of grains and walls, packing, time step, pore-fluid grid, whole-config checks, the slip rule."""
