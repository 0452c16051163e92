"""Arithmetic whose bits do not depend on the CPU, for every value that feeds evolving state.

IEEE 754 rounds +, -, *, / and sqrt correctly, so they give the same bits everywhere. numpy's
transcendental ufuncs do not: on a CPU with AVX-512 numpy dispatches ``power``, ``exp``,
``log``, ``arctan2`` and ``cbrt`` to SIMD (SVML) code whose last bit differs from the AVX2 /
scalar path (measured: ``r ** 3`` on 1e5 radii differs between ``NPY_ENABLE_CPU_FEATURES=X86_V3``
and the host). A one-ulp change of a grain's mass is amplified by the layer's chaos into a
different slip sequence, so Python-side set-up code uses only the functions below.
"""

from __future__ import annotations

import math
from decimal import Context, Decimal

import numpy as np

_CONTEXT = Context(prec=34)


def cube(x):
    """x**3 as two correctly rounded products (float or ndarray)."""
    return x * x * x


def power(x: float, exponent: float) -> float:
    """x**exponent for a scalar x > 0, evaluated in decimal software arithmetic (34 digits) and
    rounded once to a double: the same bits on every machine, unlike libm's pow."""
    if x <= 0.0:
        return 0.0 if x == 0.0 else math.nan
    return float(_CONTEXT.power(Decimal(x), Decimal(exponent)))


def sphere_mass(radius: np.ndarray, density: float) -> np.ndarray:
    """m = rho pi D^3 / 6 [rho_s d^3] of discs of radius [d] (thesis: discs carry sphere mass)."""
    return density * np.pi * cube(2.0 * radius) / 6.0
