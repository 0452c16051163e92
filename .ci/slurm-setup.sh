#!/usr/bin/env bash
# Install Debian's slurm-wlm and munge when they are missing, for the SLURM tests
# (tests/workflows/test_slurm.py starts a single-node cluster of its own as root; without root or
# these packages those tests are skipped with the reason). Idempotent and quiet: does nothing when
# the binaries are there, or when it cannot install (not root, no apt-get).
set -euo pipefail
need=()
for bin in munged slurmctld slurmd sbatch; do
    command -v "$bin" >/dev/null 2>&1 || need+=("$bin")
done
[ ${#need[@]} -eq 0 ] && exit 0
if [ "$(id -u)" -ne 0 ] || ! command -v apt-get >/dev/null 2>&1; then
    echo "slurm-setup: ${need[*]} missing and apt-get unavailable (or not root): the SLURM tests will be skipped" >&2
    exit 0
fi
export DEBIAN_FRONTEND=noninteractive
apt-get update -qq >/dev/null
apt-get install -y -qq --no-install-recommends slurm-wlm munge >/dev/null
