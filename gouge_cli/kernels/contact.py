"""The contact law's one selection point (thesis Eqs. 8-11, docs/physics/contacts.md).

A law is a module of kernels/ with, together:
  pair_constants(r_i, r_j, m_i, m_j) -> (R_ij, m_ij), the pair's effective radius and mass;
  force(dx, dz, dvx, dvz, spin_i, spin_j, r_i, r_j, r_ij, m_ij, shear, dt, c_normal, c_tangential,
        damping, friction) -> (fx_j, fz_j, torque_i, torque_j, new_shear, overlap, normal_force);
  energy(r_ij, overlap, shear, c_normal, c_tangential) -> elastic energy of a touching pair;
  constants(youngs_modulus, poisson_ratio, tangential_factor) -> (c_normal, c_tangential);
  stiffness(normal_force, r_ij, c_normal, c_tangential, power) -> (overlap, k_normal, k_tangential) at a
        normal force, for the step's stability bound (model.timestep);
the first three numba functions (inline), the last two plain Python. LAWS registers the laws;
LAW is the one in force, and every caller (the CPU and GPU steps, the observables and snapshot
forces of kernels.measure, model.timestep's constants and bound) takes it from here: a second law
is a new module and a line in LAWS.
"""

from __future__ import annotations

from collections import namedtuple

from . import hertz_mindlin

ContactLaw = namedtuple("ContactLaw", ("name", "pair_constants", "force", "energy", "constants", "stiffness"))


def register(module) -> ContactLaw:
    """The law a module defines (module docstring), under the module's name."""
    return ContactLaw(module.__name__.rsplit(".", 1)[-1], *(getattr(module, f) for f in ContactLaw._fields[1:]))


LAWS = {law.name: law for law in map(register, (hertz_mindlin,))}
LAW = LAWS["hertz_mindlin"]

pair_constants = LAW.pair_constants
pair_force = LAW.force
pair_energy = LAW.energy
