#!/usr/bin/env bash
# Time LAMMPS on the benchmark layer of `gouge bench`; prints one line
#   lammps N=<atoms> np=<ranks> style=<style> dt=<dt> steps=<steps> grain_steps_per_s=<rate>
# Usage: run.sh N [RANKS=1] [STEPS=10000] [DT=0.89] [SKIN=0.2] [STYLE=granular|hh]
# Needs `lmp` on PATH (Debian/Ubuntu: apt-get install lammps; add openmpi-bin for RANKS > 1).
# Only the steady sheared phase is timed (LAMMPS's own "Loop time" of timed.lmp).
set -euo pipefail
here=$(cd "$(dirname "$0")" && pwd)
N=${1:?usage: run.sh N [RANKS] [STEPS] [DT] [SKIN] [STYLE]}
RANKS=${2:-1}; STEPS=${3:-10000}; DT=${4:-0.89}; SKIN=${5:-0.2}; STYLE=${6:-granular}
command -v lmp >/dev/null || { echo "lmp not found: apt-get install lammps" >&2; exit 127; }
work=$(mktemp -d); trap 'rm -rf "$work"' EXIT
export OMPI_ALLOW_RUN_AS_ROOT=1 OMPI_ALLOW_RUN_AS_ROOT_CONFIRM=1
cd "$here"
python3 make_layer.py "$N" "$work/layer.data" >/dev/null
W=$(python3 -c "print(round(200 * ($N / 1e4) ** 0.5))")
ncomp=$((W * 30)); nrelax=$((W * 20 > 4000 ? W * 20 : 4000)); nshear=$((W * 80))
common=(-var dt "$DT" -var skin "$SKIN" -var sigma 3e-4 -nocite -screen none)
if command -v mpirun >/dev/null; then prep=(mpirun -np 2 --bind-to core lmp); else prep=(lmp); fi
"${prep[@]}" -in prepare.lmp "${common[@]}" -var data "$work/layer.data" -var rst "$work/layer.rst" \
    -var V 1e-3 -var vc 0.005 -var ncomp $ncomp -var nrelax $nrelax -var nshear $nshear -log "$work/prepare.log"
if [ "$RANKS" = 1 ]; then timed=(lmp); else timed=(mpirun -np "$RANKS" --bind-to core lmp); fi
"${timed[@]}" -in timed.lmp "${common[@]}" -var rst "$work/layer.rst" -var nsteps "$STEPS" -var style "$STYLE" \
    -log "$work/timed.log"
loop=$(grep -m1 '^Loop time' "$work/timed.log")
python3 - "$loop" "$STYLE" "$DT" <<'PY'
import re, sys
loop, style, dt = sys.argv[1:]
sec, ranks, steps, atoms = re.search(r"Loop time of ([\d.eE+-]+) on (\d+) procs for (\d+) steps with (\d+) atoms",
                                     loop).groups()
rate = int(atoms) * int(steps) / float(sec)
print(f"lammps N={atoms} np={ranks} style={style} dt={dt} steps={steps} grain_steps_per_s={rate:.4e}")
PY
