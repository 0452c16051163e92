"""Scene-wide observables, computed at output cadence only (never inside the step loop)."""

from __future__ import annotations

import math

import numpy as np
from numba import njit

from . import NUMBA_CACHE
from .layout import (BOTTOM_FX, BOTTOM_FZ, CONTACT_ENERGY, COORDINATION, KINETIC, MAX_OVERLAP, NONFINITE, POROSITY,
                     THICKNESS, WORST_I, WORST_J, Z_BOTTOM, Z_TOP)
from .contact import pair_constants, pair_energy, pair_force
from .neighbors import minimum_image



@njit(cache=NUMBA_CACHE)
def observe(x, z, vx, vz, spin, radius, mass, body, force_x, force_z, start, index, shear, width,
            c_normal, c_tangential, out):
    """Fill out[N_OBSERVABLES]: kinetic energy of free grains (translation + rotation) [E d^3],
    contacts per free grain, largest overlap / smaller radius [-] and its pair (WORST_I, WORST_J),
    porosity between the wall centre lines (wall grains count half) [-], thickness [d], wall
    lines, grain force on the bottom wall [E d^2], the number of non-finite grain coordinates or
    velocities, and the elastic contact energy (kernels.contact.pair_energy) [E d^3]."""
    n = x.shape[0]
    kinetic = 0.0
    n_free = 0
    solid = 0.0
    z_bot = 0.0
    z_top = 0.0
    n_bot = 0
    n_top = 0
    bfx = 0.0
    bfz = 0.0
    bad = 0
    for i in range(n):
        if not (math.isfinite(x[i]) and math.isfinite(z[i]) and math.isfinite(vx[i])
                and math.isfinite(vz[i]) and math.isfinite(spin[i])):
            bad += 1
        area = math.pi * radius[i] * radius[i]
        if body[i] == 0:
            n_free += 1
            inertia = mass[i] * 0.4 * radius[i] * radius[i]
            kinetic += 0.5 * mass[i] * (vx[i] * vx[i] + vz[i] * vz[i]) + 0.5 * inertia * spin[i] * spin[i]
            solid += area
        elif body[i] == 1:
            z_bot += z[i]
            n_bot += 1
            solid += 0.5 * area
            bfx += force_x[i]
            bfz += force_z[i]
        else:
            z_top += z[i]
            n_top += 1
            solid += 0.5 * area
    z_bot /= max(n_bot, 1)
    z_top /= max(n_top, 1)
    contacts = 0
    worst = 0.0
    worst_i = -1
    worst_j = -1
    energy = 0.0
    for i in range(n):
        for k in range(start[i], start[i + 1]):
            j = index[k]
            dx = minimum_image(x[j] - x[i], width)
            dz = z[j] - z[i]
            overlap = radius[i] + radius[j] - math.sqrt(dx * dx + dz * dz)
            if overlap > 0.0:
                contacts += (body[i] == 0) + (body[j] == 0)
                relative = overlap / min(radius[i], radius[j])
                if relative > worst:
                    worst, worst_i, worst_j = relative, i, j
                r_ij, _ = pair_constants(radius[i], radius[j], 1.0, 1.0)
                energy += pair_energy(r_ij, overlap, shear[k], c_normal, c_tangential)
    thickness = z_top - z_bot
    out[KINETIC] = kinetic
    out[COORDINATION] = contacts / max(n_free, 1)
    out[MAX_OVERLAP] = worst
    out[POROSITY] = 1.0 - solid / (width * thickness) if thickness > 0 else np.nan
    out[THICKNESS] = thickness
    out[Z_BOTTOM] = z_bot
    out[Z_TOP] = z_top
    out[BOTTOM_FX] = bfx
    out[BOTTOM_FZ] = bfz
    out[NONFINITE] = bad
    out[CONTACT_ENERGY] = energy
    out[WORST_I] = worst_i
    out[WORST_J] = worst_j


@njit(cache=NUMBA_CACHE)
def contact_list(x, z, radius, start, index, shear, width, c_normal, c_tangential, friction,
                 out_i, out_j, out_fx, out_fz):
    """Touching pairs and the elastic part of their force on j [E d^2], for snapshots: the
    contact law (kernels.contact.pair_force) at zero relative velocity, no dashpot and no
    history increment, from the stored overlap and history (the step loop keeps no per-pair
    forces). Returns the count."""
    m = 0
    for i in range(x.shape[0]):
        for k in range(start[i], start[i + 1]):
            j = index[k]
            r_ij, _ = pair_constants(radius[i], radius[j], 1.0, 1.0)
            fx, fz, _, _, _, overlap, _ = pair_force(
                minimum_image(x[j] - x[i], width), z[j] - z[i], 0.0, 0.0, 0.0, 0.0, radius[i], radius[j],
                r_ij, 0.0, shear[k], 0.0, c_normal, c_tangential, 0.0, friction)
            if overlap > 0.0:
                out_i[m] = i
                out_j[m] = j
                out_fx[m] = fx
                out_fz[m] = fz
                m += 1
    return m
