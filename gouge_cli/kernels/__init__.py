"""numba kernels: they take arrays and scalars, write into preallocated arrays and return a status."""
