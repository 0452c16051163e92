"""The scene: arrays of grains and walls, packing, time step, pore-fluid grid, whole-config checks."""
