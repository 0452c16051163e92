#!/usr/bin/env bash
# The GPU check on a machine with one CUDA GPU and no network, in about 8 minutes; results under $OUT.
#
#   OUT=/some/dir WHEELS=wheels/ bash scripts/gpu_check.sh
#
# WHEELS: a folder of wheels to install first (pydantic and its dependencies; pip --no-index).
# Stages (each under its own time limit; a failed stage is recorded and the next one runs):
#   1. tests/gpu/sim_check.py lockstep, ensemble on the device (GOUGE_GPU_DEVICE=1)
#   2. scripts/gpu_check.py: 300-grain layer vs CPU over 1e4 steps, ensemble of 3, the bench scene at
#      10,000 grains: CPU rates (2 threads, all cores), GPU B = 1, 8, 32, one step per launch,
#      GPU vs CPU state hash, the same GPU run twice -> $OUT/gpu_check.json
#   3. demo scene: `gouge run` on the GPU and on the CPU (40,000 t0 of loading), final state hashes
#      compared, then `gouge restart --slip 1` of the GPU run on the CPU
set -u
OUT=${OUT:-out}
mkdir -p "$OUT"
PY=${PYTHON:-python}
export PYTHONPATH=$PWD
log() { echo "[$(date -u +%H:%M:%S)] $*" | tee -a "$OUT/gpu_check.log"; }

if [ -n "${WHEELS:-}" ] && ls "$WHEELS"/*.whl >/dev/null 2>&1; then
  log "installing wheels from $WHEELS"
  $PY -m pip install --no-index --find-links "$WHEELS" "$WHEELS"/*.whl >>"$OUT/pip.log" 2>&1 || log "pip failed (see pip.log)"
fi
nvidia-smi >"$OUT/nvidia-smi.txt" 2>&1
$PY -c "import numba, numba_cuda, pydantic; print(numba.__version__, numba_cuda.__version__, pydantic.__version__)" \
  >"$OUT/versions.txt" 2>&1
log "versions: $(cat "$OUT/versions.txt" | tail -1)"

for mode in lockstep ensemble; do
  log "device test: $mode"
  GOUGE_GPU_DEVICE=1 timeout 150 $PY tests/gpu/sim_check.py $mode >"$OUT/device_$mode.json" 2>"$OUT/device_$mode.err"
  log "  rc=$? $(head -c 300 "$OUT/device_$mode.json")"
done

log "gpu_check.py"
timeout 240 $PY scripts/gpu_check.py "$OUT" >"$OUT/gpu_check.out" 2>&1
log "  rc=$? $(grep -o '"bitwise": [a-z]*\|"gpu_equals_cpu": [a-z]*\|"gpu_twice_same": [a-z]*' "$OUT/gpu_check.json" | tr '\n' ' ')"

log "demo on the GPU and the CPU"
DEMO_SET=(--set run.duration=40000 --set output.snapshot_interval=1e6 --quiet --force)
timeout 120 $PY -m gouge_cli.cli run configs/demo.yaml --out "$OUT/demo_gpu" --set numerics.device=gpu "${DEMO_SET[@]}" \
  >"$OUT/demo_gpu.log" 2>&1; log "  gpu rc=$? $(tail -1 "$OUT/demo_gpu.log")"
timeout 120 $PY -m gouge_cli.cli run configs/demo.yaml --out "$OUT/demo_cpu" "${DEMO_SET[@]}" \
  >"$OUT/demo_cpu.log" 2>&1; log "  cpu rc=$? $(tail -1 "$OUT/demo_cpu.log")"
$PY - "$OUT" <<'PYEOF' 2>&1 | tee -a "$OUT/gpu_check.log"
import sys, h5py
out = sys.argv[1]
hashes = {}
for d in ("gpu", "cpu"):
    try:
        with h5py.File(f"{out}/demo_{d}/run.h5", "r") as h5:
            hashes[d] = str(h5.attrs.get("final_state_hash"))
    except Exception as exc:
        hashes[d] = f"unreadable: {exc}"
print("demo final_state_hash", hashes, "equal" if hashes["gpu"] == hashes["cpu"] else "DIFFERENT")
PYEOF
$PY -m gouge_cli.cli slips "$OUT/demo_gpu" >"$OUT/demo_gpu_slips.txt" 2>&1
log "fork slip 1 of the GPU run on the CPU"
timeout 90 $PY -m gouge_cli.cli restart "$OUT/demo_gpu" --slip 1 --duration 3000 --quiet >"$OUT/fork.log" 2>&1
log "  fork rc=$? $(tail -2 "$OUT/fork.log" | tr '\n' ' ')"
log "done"
