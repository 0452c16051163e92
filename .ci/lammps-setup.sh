#!/usr/bin/env bash
# Install Debian's lammps (with its GRANULAR package) when `lmp` is missing, so that CI runs the
# LAMMPS deck of `gouge bench` for real (tests/studies/test_lammps_deck.py; skipped with the reason
# without it). Does nothing when lmp is there, or when it cannot install (not root, no apt-get).
set -euo pipefail
command -v lmp >/dev/null 2>&1 && exit 0
if [ "$(id -u)" -ne 0 ] || ! command -v apt-get >/dev/null 2>&1; then
    echo "lammps-setup: lmp missing and apt-get unavailable (or not root): the real-LAMMPS test will be skipped" >&2
    exit 0
fi
export DEBIAN_FRONTEND=noninteractive
apt-get install -y -qq --no-install-recommends lammps >/dev/null 2>&1 || { apt-get update -qq >/dev/null; apt-get install -y -qq --no-install-recommends lammps >/dev/null; }
