#!/usr/bin/env bash
# Per-stage frame times of the whole pipeline (issue #18) on the rendered demo (320x240) and the real sequences
# of the data folder, default settings, each run REPEATS times; with a BASELINE binary, that one too, its runs
# interleaved with the others' (same machine, same load). scripts/timing_table.py writes the medians over the
# runs of each run's per-frame medians (report.json's stages_ms, as `mcslam run --timings` prints them) to the doc.
# Usage: [BASELINE_NAME=NAME] [CURRENT_NAME=NAME] [CURRENT_FLAGS=..] [BASELINE_FLAGS=..] \
#        scripts/timing.sh [path/to/mcslam] [out-dir] [repeats] [data-dir] [doc] [baseline-mcslam]
#   (about 1.5 minutes a binary at 3 repeats on 2 cores). The FLAGS are added to every `mcslam run` of that binary
#   (e.g. the same binary as its own baseline, CURRENT_FLAGS=--pipelined: docs/timing_pipelined.md).
set -euo pipefail
MCSLAM=${1:-build/mcslam}
OUT=${2:-out/timing}
REPEATS=${3:-3}
DATA=${4:-${MCSLAM_DATA:-../shared/data}}
DOC=${5:-docs/timing.md}
BASELINE=${6:-}
mkdir -p "$OUT"
runs="$OUT/runs.tsv"
: > "$runs"
one() {  # name, input, run arguments...
  local name=$1 input=$2
  shift 2
  for r in $(seq 1 "$REPEATS"); do
    for label in ${BASELINE:+baseline} current; do
      local bin=$MCSLAM flags=${CURRENT_FLAGS:-}
      [[ $label == baseline ]] && bin=$BASELINE flags=${BASELINE_FLAGS:-}
      local dir="$OUT/$label/$name/$r"
      mkdir -p "$dir"
      # shellcheck disable=SC2086  # the flags are words
      "$bin" run "$input" "$@" $flags --out "$dir" > "$dir.stdout" 2> "$dir.log" || true
      printf '%s\t%s\t%s\n' "$label" "$name" "$dir/report.json" >> "$runs"
      echo "$label $name run $r: $(grep -o 'fps=[0-9.]*' "$dir.stdout" | head -1)"
    done
  done
}
"$MCSLAM" synth --scenario paper --seed 1 --render --out "$OUT/demo_scenario" > /dev/null
one demo "$OUT/demo_scenario" --dataset synthetic
if [[ -d "$DATA/kitti_odometry_06_frames000-050" ]]; then one kitti06 "$DATA/kitti_odometry_06_frames000-050"; fi
echo "525 525 320 240" > "$OUT/7scenes_camera.txt"
if [[ -d "$DATA/7scenes_redkitchen_frames000-299" ]]; then
  one 7scenes "$DATA/7scenes_redkitchen_frames000-299" --camera "$OUT/7scenes_camera.txt"
fi
commit=$(git -C "$(dirname "$0")" rev-parse --short HEAD 2>/dev/null || echo unknown)
/usr/bin/python3 "$(dirname "$0")/timing_table.py" "$runs" "$DOC" "$commit" "${BASELINE_NAME:-$BASELINE}" \
  "${CURRENT_NAME:-}" "${CURRENT_FLAGS:-}" "${BASELINE_FLAGS:-}"
