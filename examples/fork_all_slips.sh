#!/usr/bin/env bash
# Fork every slip of a run at two permeabilities and collect the pair summaries.
#
#   examples/fork_all_slips.sh runs/demo [1e-5 1e-3]
#
# Uses only documented exit codes: 0 done, 2 bad input (stop), 3 physics failure (logged,
# the loop goes on), 130 interrupted (stop). Output: RUN/forks/summary.jsonl, one pair per line.
set -uo pipefail
run=${1:?usage: $0 RUN_DIR [PERM ...]}
shift
perms=("$@")
[ ${#perms[@]} -eq 0 ] && perms=(1e-5 1e-3)
gouge=${GOUGE:-gouge}
py=${PYTHON:-python3}

slips=$("$gouge" slips "$run" --json | "$py" -c 'import json,sys; print(" ".join(str(e["number"]) for e in json.load(sys.stdin) if e["checkpoint"]))') || exit 2
[ -n "$slips" ] || { echo "no slips with checkpoints in $run" >&2; exit 0; }

args=()
for k in "${perms[@]}"; do args+=(--perm "$k"); done
summary="$run/forks/summary.jsonl"
mkdir -p "$run/forks"
: > "$summary"
collect() { "$py" -c 'import json,sys; print(json.dumps(json.load(open(sys.argv[1]))))' "$1" >> "$summary"; }
for n in $slips; do
    pair="$run/forks/slip_$(printf %03d "$n")/pair.json"
    if [ -f "$pair" ]; then echo "slip $n: already forked, collecting"; collect "$pair"; continue; fi
    echo "slip $n: forking at ${perms[*]}"
    "$gouge" restart "$run" --slip "$n" "${args[@]}" --quiet > /dev/null
    rc=$?
    case $rc in
        0) collect "$pair" ;;
        3) echo "slip $n: physics failure (see the branch run.h5 status); going on" >&2 ;;
        130) echo "interrupted" >&2; exit 130 ;;
        *) echo "slip $n: gouge restart failed with exit code $rc" >&2; exit $rc ;;
    esac
done
echo "pair summaries: $summary ($(wc -l < "$summary") pairs)"
