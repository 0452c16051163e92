#!/usr/bin/env bash
# The GPU machine's visit in one script (~9 minutes at most): results under $OUT, most important first.
#
#   OUT=/some/dir WHEELS=.whl BUDGET=530 bash scripts/gpu_check.sh
#
# WHEELS: a folder of wheels the machine lacks (pydantic and its dependencies), installed with
# pip --no-index into /tmp/site. BUDGET: seconds for everything; each stage gets what is left.
# $OUT receives at most 8 files (what the device tool brings back): gpu_check.log (the story),
# gpu_check.json (scripts/gpu_check.py: device tests on the GPU, both rebuild modes, the
# 10,000-grain bench for B = 1..128 with per-phase cycles, bits against the CPU, twice),
# many_core.json + summary.txt (benchmarks/many_core.py, shortened) and logs.tar.gz (the rest).
# Stages: 1. scripts/gpu_check.py; 2. the demo scene loaded on the GPU and on the CPU side by
# side (40,000 t0), final state hashes compared, then `gouge restart --slip 1` of the GPU run on
# the CPU; 3. benchmarks/many_core.py (1-16 threads at 10,000 and 40,000 grains, 8 runs of 2
# threads side by side), with what time is left.
# Rehearse with NUMBA_ENABLE_CUDASIM=1 (every stage at toy size under numba-cuda's simulator).
set -u
OUT=${OUT:-out}
mkdir -p "$OUT"
W=${WORK:-/tmp/gouge_gpu_check}
rm -rf "$W"; mkdir -p "$W"
PY=${PYTHON:-python3}
BUDGET=${BUDGET:-530}
export PYTHONPATH=$PWD PYTHONUNBUFFERED=1
SIM=${NUMBA_ENABLE_CUDASIM:-0}
STAGES=${STAGES:-123}   # which stages to run (a rehearsal of one stage: STAGES=2)
log() { echo "[$(date -u +%H:%M:%S) +${SECONDS}s] $*" | tee -a "$OUT/gpu_check.log"; }
left() { local l=$((BUDGET - SECONDS - ${1:-0})); [ "$l" -lt 5 ] && l=5; echo "$l"; }
pack() { tar -czf "$OUT/logs.tar.gz" -C "$W" --exclude='*.h5' --exclude='*.npz' . 2>/dev/null; }

if [ -n "${WHEELS:-}" ] && ls "$WHEELS"/*.whl >/dev/null 2>&1; then
  $PY -m pip install -q --no-index --no-deps --no-compile --no-cache-dir --upgrade --target /tmp/site "$WHEELS"/*.whl \
    >"$W/pip.log" 2>&1 && export PYTHONPATH=$PWD:/tmp/site || log "pip failed (see pip.log)"
fi
# numba-cuda releases that still register np.row_stack (and a few other aliases) fail to import
# under numpy >= 2.4, which removed them; the aliases are put back for this script's processes only
mkdir -p /tmp/site
cat >/tmp/site/sitecustomize.py <<'PYEOF'
import numpy
for old, new in (("row_stack", "vstack"), ("trapz", "trapezoid"), ("in1d", "isin")):
    if old not in numpy.__dict__ and hasattr(numpy, new):
        setattr(numpy, old, getattr(numpy, new))
PYEOF
case ":$PYTHONPATH:" in *:/tmp/site:*) ;; *) export PYTHONPATH=$PYTHONPATH:/tmp/site ;; esac
nvidia-smi >"$W/nvidia-smi.txt" 2>&1
log "gpu: $(nvidia-smi --query-gpu=name,driver_version,clocks.max.sm --format=csv,noheader 2>/dev/null | head -1)"
log "cpu: $(grep -m1 'model name' /proc/cpuinfo | cut -d: -f2) x $(nproc); commit $(git rev-parse --short HEAD 2>/dev/null)"
log "versions: $($PY -c 'import numba, numpy, pydantic; from numba import cuda; print("numba", numba.__version__, "numpy", numpy.__version__, "pydantic", pydantic.__version__, "cuda available", cuda.is_available())' 2>&1 | tail -1)"

if [[ $STAGES == *1* ]]; then
log "1. gpu_check.py (device tests, bench, bits)"
timeout "$(left $([[ $STAGES == 1 ]] && echo 3 || echo 200))" $PY scripts/gpu_check.py "$OUT" >"$W/gpu_check.out" 2>&1
log "  rc=$? $(grep -o '"bitwise": [a-z]*\|"gpu_equals_cpu": [a-z]*\|"gpu_twice_same": [a-z]*' "$OUT/gpu_check.json" | tr '\n' ' ')"
pack
fi

if [[ $STAGES == *2* ]]; then
log "2. demo on the GPU and on the CPU, side by side"
DEMO_SET=(--set run.duration=40000 --set output.snapshot_interval=1e6 --quiet --force)
[ "$SIM" = 1 ] && DEMO_SET=(--set run.duration=40 --set packing.n_grains=40 --set packing.width=6 --set compaction.min_time=100
                             --set compaction.max_time=100
                             --set output.snapshot_interval=1e6 --quiet --force)
T=$(left 150)
GOUGE_GPU_PARALLEL=1 timeout "$T" $PY -m gouge_cli.cli run configs/demo.yaml --out "$W/demo_gpu" \
  --set numerics.device=gpu "${DEMO_SET[@]}" >"$W/demo_gpu.log" 2>&1 &
GPU_PID=$!
NUMBA_NUM_THREADS=4 timeout "$T" $PY -m gouge_cli.cli run configs/demo.yaml --out "$W/demo_cpu" "${DEMO_SET[@]}" \
  >"$W/demo_cpu.log" 2>&1
CPU_RC=$?
wait $GPU_PID; GPU_RC=$?
log "  gpu rc=$GPU_RC cpu rc=$CPU_RC"
$PY - "$W" <<'PYEOF' 2>&1 | tee -a "$OUT/gpu_check.log"
import sys, h5py
w = sys.argv[1]
hashes = {}
for d in ("gpu", "cpu"):
    try:
        with h5py.File(f"{w}/demo_{d}/run.h5", "r") as h5:
            hashes[d] = str(h5.attrs.get("final_state_hash"))
    except Exception as exc:
        hashes[d] = f"unreadable: {exc}"
print("  demo final_state_hash", hashes, "equal" if hashes["gpu"] == hashes["cpu"] else "DIFFERENT")
PYEOF
$PY -m gouge_cli.cli slips "$W/demo_gpu" >"$W/demo_gpu_slips.txt" 2>&1
log "  fork slip 1 of the GPU run on the CPU"
timeout "$(left 120)" $PY -m gouge_cli.cli restart "$W/demo_gpu" --slip 1 --duration 3000 --quiet >"$W/fork.log" 2>&1
log "  fork rc=$? $(tail -2 "$W/fork.log" | tr '\n' ' ')"
pack
fi

if [[ $STAGES == *3* ]]; then
log "3. many_core.py with $(left) s left"
MC=(--sizes 10000,40000 --threads 1,2,4,8,16 --steps 600 --repeats 1 --no-lammps --concurrent 8 --seconds 5)
[ "$SIM" = 1 ] && MC=(--sizes 400 --threads 1,2 --steps 50 --repeats 1 --no-lammps --concurrent 2 --seconds 2)
OUT="$W/mc" timeout "$(left 3)" $PY benchmarks/many_core.py "${MC[@]}" >"$W/many_core.log" 2>&1
log "  rc=$? $(tail -4 "$W/many_core.log" | tr '\n' ' ' | cut -c1-600)"
cp "$W/mc/many_core.json" "$W/mc/summary.txt" "$OUT/" 2>/dev/null
[ -f "$OUT/summary.txt" ] || cp "$W/mc/bench.json" "$OUT/many_core_bench.json" 2>/dev/null
pack
fi
log "done"
